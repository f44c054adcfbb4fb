/* selftest.cl: the smallest useful kernel, run by `clwave info --check` and tools/setup.sh.
 *
 * Parameters: a (in), b (in), out (out): (n,) float32
 * Grid:       global (n,), any local size
 * Assumes:    nothing; proves the compiler and the queue work. */
#include "common/clw_common.h"

__kernel void selftest_axpy(const float alpha, __global const float *a,
                            __global const float *b, __global float *out)
{
    const size_t i = get_global_id(0);
    out[i] = alpha * a[i] + b[i];
}
