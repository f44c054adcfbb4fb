/* types.h: what every ray-tracer source shares: the precision-dependent real types (CLW_DOUBLE for
 * a float64 build), the samples per segment and their lanes, and the orders of the channel groups.
 * Build: CLW_SAMPLES (9, 10 or 16), CLW_GROUPS and CLW_ORDERS, CLW_JOIN when every order is >= 3. */
#ifndef CLW_RAYTRACE_TYPES_H
#define CLW_RAYTRACE_TYPES_H
#include "common/clw_common.h"

#ifdef CLW_DOUBLE
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
typedef double real;
typedef double2 real2;
typedef double3 real3;
typedef double4 real4;
typedef double8 real8;
typedef double16 real16;
#define REAL_EPSILON DBL_EPSILON
#define to_real4(v) convert_double4(v)
#define to_real3(v) convert_double3(v)
#define convert_real3 convert_double3
#define fast_exp exp
#define fast_exp2 exp2
#define fast_log2 log2
#else
typedef float real;
typedef float2 real2;
typedef float3 real3;
typedef float4 real4;
typedef float8 real8;
typedef float16 real16;
#define REAL_EPSILON FLT_EPSILON
#define to_real4(v) (v)
#define to_real3(v) (v)
#define convert_real3 convert_float3
#define fast_exp native_exp
#define fast_exp2 native_exp2
#define fast_log2 native_log2
#endif

#define NS CLW_SAMPLES
#define P0 8 /* the lane of xi = -1 */
#ifdef CLW_JOIN
#define JOIN 1
#else
#define JOIN 0
#endif

/* The samples of a segment in the lanes of one vector (lanes NS.. repeat lane 0, unused) */
typedef real16 realv;
/* Orders up to 4 (pieces of degree 9 at most, NS 9 or 10) or order 6 among the groups (degree 15, NS = 16):
 * the largest order, and the lanes 0..NG-1 that give alpha's gradient series (degree 8, or 14) */
#define MAX_ORDER (NS > 10 ? 6 : 4)
#define NG (NS > 10 ? NS - 1 : 9)

constant int ORDER[CLW_GROUPS] = {CLW_ORDERS};
#endif
