"""The X-ray views' colour maps (docs/viewer.md §2): 256 colours each, looked up by the 8-bit grey level of the
windowed line integrals (:func:`apply`).

``grey`` is the grey level itself; the others are matplotlib's tables (3.11: viridis, inferno and magma by van der Walt
and Smith, CC0; bone after MATLAB's), sampled once at their 256 entries and rounded to 8 bits,
``np.round(255 * matplotlib.colormaps[name](np.arange(256))[:, :3])``, stored here as base64 of the (256, 3) uint8
rows (the page's colour bar gets them so, :func:`page_tables`): matplotlib is no dependency of clwave
(tests/test_view.py compares them with it where it is installed).  Each also reversed, named as matplotlib and napari
name it, ``_r`` after its name (``grey_r``: dark bright, as a cryo-EM map's protein is shown): one rule, its table
upside down.  The viewer's X-ray views and the pictures of :meth:`clwave.RenderResult.picture` use them.
"""

from __future__ import annotations

import base64
from functools import cache

import numpy as np

from ..errors import InputError

_TABLES = {
    "bone": (
        "AAAAAQEBAgICAwMEBAMFBAQGBQUHBgYJBwcKCAgLCQkMCgoNCgoPCwsQDAwRDQ0SDg4TDw8VEBAWEREXEhEYEhIaExMbFBQcFRUd"
        "FhYeFxcgGBghGBgiGRkjGholGxsmHBwnHR0oHh4pHx8rIB8sICAtISEuIiIvIyMxJCQyJSUzJiY0JiY2Jyc3KCg4KSk5Kio6Kys8"
        "LCw9LS0+Li0/Li5BLy9CMDBDMTFEMjJFMzNHNDRINDRJNTVKNjZLNzdNODhOOTlPOjpQOztSPDtTPDxUPT1VPj5WPz9YQEBZQUFa"
        "QkJbQkJdQ0NeRERfRUVgRkZhR0djSEhkSUllSklmSkpnS0tpTExqTU1rTk5sT09uUFBvUFBwUVFxUlNyU1RzVFV0VVZ1Vld2V1l2"
        "V1p3WFt4WVx5Wl16W197XGB8XWF9XmJ9XmN+X2V/YGaAYWeBYmiCY2mDZGuEZWyEZm2FZm6GZ2+HaHGIaXKJanOKa3SLbHWLbHeM"
        "bXiNbnmOb3qPcHuQcX2Rcn6Sc3+Sc4CTdIGUdYOVdoSWd4WXeIaYeYeZeomZeoqae4ubfIycfY2dfo+ef5CfgJGggZKggZShgpWi"
        "g5ajhJekhZilhpqmh5uniJyniJ2oiZ6piqCqi6GrjKKsjaOtjqSuj6auj6evkKiwkamxkqqyk6yzlK20la61lq+1lrC2l7K3mLO4"
        "mbS5mrW6m7a7nLi8nbm8nbq9nru+n7y/oL7Aob/BosDCo8HDpMLDpMTEpcXFpsbGp8fHqcjIqsnJrMrKrcrKrsvLsMzMsc3Nss7O"
        "tM/PtdDQt9HRuNLRudLSu9PTvNTUvdXVv9bWwNfXwdjYw9jYxNnZxtrax9vbyNzcyt3dy97ezN/fzuDfz+Dg0eHh0uLi0+Pj1eTk"
        "1uXl1+bm2ebm2ufn2+jo3enp3urq4Ovr4ezs4u3t5O7t5e7u5u/v6PDw6fHx6vLy7PPz7fT07/T08PX18fb28/f39Pj49fn59/r6"
        "+Pv7+vz7+/z8/P39/v7+////"
    ),
    "viridis": (
        "RAFURAJWRQRXRQVZRgdaRghcRgpdRgteRw1gRw5hRxBjRxFkRxNlSBRnSBZoSBdpSBhqSBpsSBttSBxuSB1vSB9wSCBxSCFzSCN0"
        "SCR1SCV2SCZ3SCh4SCl5Ryp6Ryx6Ry17Ry58Ry99RjB+RjJ+RjN/RjSARTWBRTeBRTiCRDmDRDqDRDuEQz2EQz6FQj+FQkCGQkGG"
        "QUKHQUSHQEWIQEaIP0eIP0iJPkmJPkqJPkyKPU2KPU6KPE+KPFCLO1GLO1KLOlOLOlSMOVWMOVaMOFiMOFmMN1qMN1uNNlyNNl2N"
        "NV6NNV+NNGCNNGGNM2KNM2ONMmSOMmWOMWaOMWeOMWiOMGmOMGqOL2uOL2yOLm2OLm6OLm+OLXCOLXGOLHGOLHKOLHOOK3SOK3WO"
        "KnaOKneOKniOKXmOKXqOKXuOKHyOKH2OJ36OJ3+OJ4COJoGOJoKOJoKOJYOOJYSOJYWOJIaOJIeOI4iOI4mOI4qNIouNIoyNIo2N"
        "IY6NIY+NIZCNIZGMIJKMIJKMIJOMH5SMH5WLH5aLH5eLH5iLH5mKH5qKHpuKHpyJHp2JH56JH5+IH6CIH6GIH6GHH6KHIKOGIKSG"
        "IaWFIaaFIqeFIqiEI6mDJKqDJauCJayCJq2BJ62BKK6AKa9/KrB/LLF+LbJ9LrN8L7R8MbV7MrZ6NLZ5Nbd5N7h4OLl3Orp2O7t1"
        "Pbx0P7xzQL1yQr5xRL9wRsBvSMFuSsFtTMJsTsNrUMRqUsVpVMVoVsZnWMdlWshkXMhjXsliYMpgY8tfZcteZ8xcac1bbM1abs5Y"
        "cM9Xc9BWddBUd9FTetFRfNJQf9NOgdNNhNRLhtVJidVIi9ZGjtZFkNdDk9dBldhAmNg+m9k8ndk7oNo5oto3pds2qNs0qtwyrdww"
        "sN0vst0ttd4ruN4put4ovd8mwN8lwt8jxeAhyOAgyuEfzeEd0OEc0uIb1eIa2OIZ2uMZ3eMY3+MY4uQY5eQZ5+QZ6uUa7OUb7+Uc"
        "8eUd9OYe9uYg+OYh++cj/ecl"
    ),
    "inferno": (
        "AAAEAQAFAQEGAQEIAgEKAgIMAgIOAwIQBAMSBAMUBQQXBgQZBwUbCAUdCQYfCgciCwckDAgmDQgpDgkrEAktEQowEgoyFAs0FQs3"
        "Fgs5GAw8GQw+GwxBHAxDHgxFHwxIIQxKIwxMJAxPJgxRKAtTKQtVKwtXLQtZLwpbMQpcMgpeNApfNglhOAliOQljOwlkPQllPglm"
        "QApnQgpoRApoRQppRwtqSQtqSgxrTAxrTQ1sTw1sUQ5sUg5tVA9tVQ9tVxBuWRBuWhFuXBJuXRJuXxNuYRNuYhRuZBVuZRVuZxZu"
        "aRZuahdubBhubRhubxlucRluchpudBpudRtudxxteBxteh1tfB1tfR5tfx5sgB9sgiBshCBrhSFrhyFriCJqiiJqjCNpjSNpjyRp"
        "kCVokiVokyZnlSZnlydmmCdmmihlmylknSlknypjoCpjoitioyxhpSxgpi1gqC5fqS5eqy9erTBdrjBcsDFbsTJaszJatDNZtjRY"
        "tzVXuTVWujZVvDdUvThTvzlSwDpRwTpQwztPxDxOxj1Nxz5MyD9LykBKy0FJzEJIzkNHz0RG0EVF0kZE00dD1EhC1UpB10s/2Ew+"
        "2U092k4821A73VE63lI431M34FU24VY14lc041kz5Fox5Vww5l0v514u6GAt6WEr6mMq62Qp62Yo7Gcm7Wkl7mok72wj724h8G8g"
        "8XEf8XMd8nQc83Yb83gZ9HkY9XsX9X0V9n4U9oAT94IS94QQ+IUP+IcO+IkM+YsL+YwK+Y4J+pAI+pIH+pQH+5YG+5cG+5kG+5sG"
        "+50H/J8H/KEI/KMJ/KUK/KYM/KgN/KoP/KwR/K4S/LAU/LIW/LQY+7Ya+7gd+7of+7wh+74j+sAm+sIo+sQq+sYt+ccv+cky+cs1"
        "+M03+M8699E999NA9tVD9tdG9dlJ9dtM9N1P9N9T9OFW8+Na8+Vd8uZh8uhl8upp8ext8e1x8e918fF58vJ98vSC8/WG8/aK9PiO"
        "9fmS9vqW+Pua+fyd+v2h/P+k"
    ),
    "magma": (
        "AAAEAQAFAQEGAQEIAgEJAgILAgINAwMPAwMSBAQUBQQWBgUYBgUaBwYcCAceCQcgCggiCwkkDAkmDQopDgsrEAstEQwvEg0xEw00"
        "FA42FQ44Fg87GA89GRA/GhBCHBBEHRFHHhFJIBFLIRFOIhFQJBJTJRJVJxJYKRFaKhFcLBFfLRFhLxFjMRFlMxBnNBBpNhBrOBBs"
        "OQ9uOw9wPQ9xPw9yQA90Qg91RA92RRB3RxB4SRB4ShB5TBF6ThF7TxJ7URJ8UhN8VBN9VhR9VxV+WRV+WhZ+XBZ/XRd/Xxh/YBiA"
        "YhmAZBqAZRqAZxuAaByBahyBax2BbR2Bbh6BcB+Bch+BcyCBdSGBdiGBeCKBeSKCeyOCfCOCfiSCgCWCgSWBgyaBhCaBhieBiCeB"
        "iSiBiymBjCmBjiqBkCqBkSuBkyuAlCyAliyAmC2AmS2Amy5/nC5/ni9/oC9/oTB+ozB+pTF+pjF9qDJ9qjN9qzN8rTR8rjR7sDV7"
        "sjV7szZ6tTZ6tzd5uDd5ujh4vDl4vTl3vzp3wDp2wjt1xDx1xTx0xz1zyD5zyj5yzD9xzUBxz0Bw0EFv0kJv00Nu1URt1kVs2EVs"
        "2UZr20dq3Ehp3klo30po4Exn4k1m405l5E9k5VBk51Jj6FNi6VRi6lZh61dg7Fhg7Vpf7lte711e8F9e8WBd8mJd8mRc82Vc9Gdc"
        "9Glc9Wtc9mxc9m5c93Bc93Jc+HRc+HZc+Xhd+Xld+Xtd+n1e+n9e+oFf+4Nf+4Vg+4dh/Ilh/Ipi/Ixj/I5k/JBl/ZJm/ZRn/ZZo"
        "/Zhp/Zpq/Ztr/p1s/p9t/qFu/qNv/qVx/qdy/qlz/qp0/qx2/q53/rB4/rJ6/rR7/rZ8/rd+/rl//ruB/r2C/r+E/sGF/sKH/sSI"
        "/saK/siM/sqN/syP/s2Q/s+S/tGU/tOV/tWX/teZ/tia/dqc/dye/d6g/eCh/eKj/eOl/eWn/eep/emq/eus/Oyu/O6w/PCy/PK0"
        "/PS2/Pa4/Pe5/Pm7/Pu9/P2/"
    ),
}
#: the names a page may choose, grey first (the default), then each reversed (``_r``)
_FORWARD = ("grey", *_TABLES)
NAMES = (*_FORWARD, *(f"{name}_r" for name in _FORWARD))


@cache
def table(name: str) -> np.ndarray:
    """The (256, 3) uint8 colours of ``name`` (one of :data:`NAMES`), read-only."""
    base = name.removesuffix("_r")
    rows = np.repeat(np.arange(256, dtype=np.uint8), 3).reshape(256, 3) if base == "grey" else \
        np.frombuffer(base64.b64decode(_TABLES[base]), np.uint8).reshape(256, 3)
    return rows[::-1] if name.endswith("_r") else rows


def page_tables() -> dict:
    """Each map's 256 colours as the page draws its colour bar from them (the hello's ``colour_maps``, docs/viewer.md
    §3): name to base64 of the (256, 3) uint8 rows, in :data:`NAMES`' order."""
    return {name: base64.b64encode(table(name).tobytes()).decode() for name in NAMES}


def apply(picture: np.ndarray, name: str, top=255) -> np.ndarray:
    """A grey picture (H, W) of levels 0..``top`` in the colours of ``name``: grey as it is, ``grey_r`` ``top`` less
    each level (at any bit depth), another (8 bits only: 256 colours) (H, W, 3)."""
    if name.removesuffix("_r") == "grey":
        return top - picture if name.endswith("_r") else picture
    return table(name)[picture]


def check_colour_map(name):
    """``name`` (None: none) as one of :data:`NAMES`, matplotlib's spelling "gray" taken as "grey"; one InputError
    (in the command line's words too) otherwise."""
    if name is None or isinstance(name, str) and name.replace("gray", "grey") in NAMES:
        return None if name is None else name.replace("gray", "grey")
    raise InputError(f"colour_map={name!r} must be one of {', '.join(NAMES)} (_r: reversed, e.g. grey_r to show "
                     f"dark bright)", cli=f"--colour-map {name} must be one of {', '.join(NAMES)} (_r: reversed, "
                                          f"e.g. grey_r to show dark bright)")
