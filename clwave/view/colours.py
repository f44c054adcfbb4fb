"""The X-ray views' colour maps (docs/viewer.md §2): 256 colours each, looked up by the 8-bit grey level of the
windowed line integrals (:func:`apply`).

``grey`` is the grey level itself; the others are matplotlib's tables (3.11: viridis, inferno and magma by van der Walt
and Smith, CC0; bone after MATLAB's; the diverging seismic, RdBu (ColorBrewer's, Apache 2.0) and coolwarm (Moreland's),
red-white-blue about their middle, for signed data), sampled once at their 256 entries and rounded to 8 bits,
``np.round(255 * matplotlib.colormaps[name](np.arange(256))[:, :3])``, stored here as base64 of the (256, 3) uint8
rows (the page's colour bar gets them so, :func:`page_tables`): matplotlib is no dependency of clwave
(tests/test_view.py compares them with it where it is installed).  Each also reversed, named as matplotlib and napari
name it, ``_r`` after its name (``grey_r``: dark bright, as a cryo-EM map's protein is shown): one rule, its table
upside down.  The viewer's X-ray views and the pictures of :meth:`clwave.RenderResult.picture` use them; a diverging
map's "auto" window is centred on 0 where the values have both signs (:func:`centred`).

:meth:`clwave.TransferFunction.from_colormap` takes matplotlib's whole catalogue instead (its names, or a ``Colormap``
of the user's own): a transfer function is built where matplotlib is, while a picture's colours (and the page's colour
bar) must be there without it, so these few are stored here.
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
    "seismic": (
        "AABMAABPAABSAABVAABYAABaAABdAABgAABjAABmAABoAABrAABuAABxAAB0AAB2AAB5AAB8AAB/AACCAACEAACHAACKAACNAACQ"
        "AACSAACVAACYAACbAACeAACgAACjAACmAACpAACsAACuAACxAAC0AAC3AAC6AAC8AAC/AADCAADFAADIAADKAADNAADQAADTAADW"
        "AADYAADbAADeAADhAADkAADmAADpAADsAADvAADyAAD0AAD3AAD6AAD9AQH/BQX/CQn/DQ3/ERH/FRX/GRn/HR3/ISH/JSX/KSn/"
        "LS3/MTH/NTX/OTn/PT3/QUH/RUX/SUn/TU3/UVH/VVX/WVn/XV3/YWH/ZWX/aWn/bW3/cXH/dXX/eXn/fX3/gYH/hYX/iYn/jY3/"
        "kZH/lZX/mZn/nZ3/oaH/paX/qan/ra3/sbH/tbX/ubn/vb3/wcH/xcX/ycn/zc3/0dH/1dX/2dn/3d3/4eH/5eX/6en/7e3/8fH/"
        "9fX/+fn//f3///39//n5//X1//Hx/+3t/+np/+Xl/+Hh/93d/9nZ/9XV/9HR/83N/8nJ/8XF/8HB/729/7m5/7W1/7Gx/62t/6mp"
        "/6Wl/6Gh/52d/5mZ/5WV/5GR/42N/4mJ/4WF/4GB/319/3l5/3V1/3Fx/21t/2lp/2Vl/2Fh/11d/1lZ/1VV/1FR/01N/0lJ/0VF"
        "/0FB/z09/zk5/zU1/zEx/y0t/ykp/yUl/yEh/x0d/xkZ/xUV/xER/w0N/wkJ/wUF/wEB/gAA/AAA+gAA+AAA9gAA9AAA8gAA8AAA"
        "7gAA7AAA6gAA6AAA5gAA4wAA4gAA4AAA3gAA3AAA2gAA2AAA1gAA0wAA0gAA0AAAzgAAzAAAygAAyAAAxgAAwwAAwgAAwAAAvgAA"
        "vAAAugAAuAAAtgAAswAAsgAAsAAArgAArAAAqgAAqAAApgAAowAAogAAoAAAngAAnAAAmgAAmAAAlgAAkwAAkgAAkAAAjgAAjAAA"
        "igAAiAAAhgAAhAAAggAAgAAA"
    ),
    "RdBu": (
        "ZwAfagEfbQIgcAMgcwQhdgUheQYifAcifwgjgQgjhAkkhwokigsljQwlkA0mkw4mlg8nmRAnnBEnnxIoohMopRQpqBUpqxYqrhcq"
        "sRgrsxkstBwtth8utyIwuCUxuigyuyo0vS01vjA2vzM4wTY5wjg6xDs8xT49xkE+yERAyUdBy0lCzExEzk9Fz1JG0FVI0lhJ01pK"
        "1V1M1mBN12NP2GVR2mhT22tV3G5X3XBZ3nNc33Ze4Xhg4nti435k5IBm5YNo5oZq6Ils6Ytu6o5w65Fy7JN07pZ375l58Jx78Z59"
        "8qF/86SB9KaD9aiG9aqJ9ayL9q+O9rGR9rOU97WW97eZ97mc+Lue+L2h+L+k+cKn+cSp+cas+siv+sqx+8y0+863+9C5/NO8/NW/"
        "/NfC/dnE/dvH/dzJ/d3L/N7N/N/P/ODQ/OLS++PU++TW++XY++ba+ufc+uje+unf+urh+evj+e3l+e7n+e/p+fDr+PHt+PLv+PPw"
        "+PTy9/X09/b29vf39fb38/X28vX28PT27/P17fL17PL16vH16fD05/D05u/05O704+3z4e3z4Ozz3uvy3evy2+ry2uny2Onx1+jx"
        "1efx1Obx0ubw0eXwz+TvzOLvyuHux+Dtxd/swt3swNzrvdvqu9rquNjpttfos9bosdXnrtPmrNLlqdHlp9Dkpc7jos3joMzincvh"
        "m8ngmMjglsffk8bekMTdjcLcisDbh77ahLzZgbrYfrjXe7bWeLTVdbLUcbDTbq7Sa6zRaKvQZanPYqfOX6XNXKPLWaHKVp/JUp3I"
        "T5vHTJnGSZfFRpXEQ5PDQpHCQI/BP47APoy/PIq+O4i+Ooe9OIW8N4O7NoG6NIC5M364Mny3MHq2L3m1Lne1LHW0K3OzKnGyKHCx"
        "J26wJmyvJGquI2mtImesIGWrH2OoHmGlHV+iHFyfG1qcGliZGVaWGFSTF1KQFVCNFE6KE0yHEkmEEUeBEEV+D0N7DkF5DT92DD1z"
        "CjtwCThtCDZqBzRnBjJkBTBh"
    ),
    "coolwarm": (
        "O0zAPE7CPVDDPlHFP1PGQFXIQlfJQ1jLRFrMRVzORl7PSF/RSWHSSmPTS2TVTGbWTmjYT2nZUGvaUW3bU27dVHDeVXLfVnPgWHXh"
        "WXfjWnjkW3rlXXzmXn3nX3/oYYDpYoLqY4TrZIXsZoftZ4juaIrvaovva43wbI/xbpDyb5LzcJPzcpX0c5b1dZf2dpn2d5r3eZz4"
        "ep34e5/5faD5fqH6gKP6gaT7gqb7hKf8haj8hqn8iKv9iaz9i639jK/+jbD+j7H+kLL+krT+k7X+lLb/lrf/l7j/mLn/mrv/m7z/"
        "nb3/nr7/n7//ocD/osH/o8L+pcP+psT+p8X+qcb9qsf9q8j9rcn9rsn8r8r8scv8ssz7s837tc36ts76t8/5udD5utD4u9H4vNL3"
        "vtL2v9P2wNT1wdT0w9X0xNXzxdbyxtbxx9fwydfwytjvy9juzNntzdnsztrrz9rq0drp0tvo09vn1Nvm1dvl1tzk19zj2Nzi2dzh"
        "2tzg29ze3N3d3dzc3tzb39vZ4NvY4drW4trV49nT5NnS5djR5tfP59fO6NbM6dXL6tXJ6tTI69PG7NPF7dLD7dHC7tDA78+/7869"
        "8M278c268cy48su38sq18sm088iy88ex9Mav9MWt9cSs9cKq9cGp9cCn9r+m9r6k9r2i97yh97qf97me97ic97eb97WZ97SX97OW"
        "97GU97CT96+R962Q96yO96qM96mL96iJ96aI9qWG9qOF9qKD9aCB9Z+A9Z1+9Zx99Jp79Jh685d485V385R18pJ08pBy8Y9x8Y1v"
        "8Itu8Ips74hr7oZp7oRo7YNm7IFl7H9j631i6ntg6Xpf6Xhd6HZc53Rb5nJZ5XBY5G5W42xV42tU4mlS4WdR4GVP32NO3mFN3V9L"
        "3F1K2lpJ2VhH2FZG11RF1lJE1VBC1E5B0ktA0Uk/0Ec9z0U8zUI7zEA6yz44yjs3yDg2xzY1xTM0xDAywy4xwSswwCgvviQuvR8t"
        "uxssuhYruBIqtw0otQkntAQm"
    ),
}
#: the names a page may choose, grey first (the default), then each reversed (``_r``)
_FORWARD = ("grey", *_TABLES)
NAMES = (*_FORWARD, *(f"{name}_r" for name in _FORWARD))
#: the diverging maps (and their ``_r``): white in the middle, for values about 0
DIVERGING = frozenset(name for name in NAMES if name.removesuffix("_r") in ("seismic", "RdBu", "coolwarm"))


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


def centred(window, colour_map) -> tuple:
    """The display window ``(lo, hi)`` of a picture in ``colour_map``: a diverging map's (:data:`DIVERGING`) centred on
    0 (``(-m, m)``, m the larger of ``-lo`` and ``hi``) where it spans 0, so that 0 is the map's middle, white, as
    seismic and phase viewers show signed values; else as it is."""
    lo, hi = window
    if colour_map not in DIVERGING or not lo < 0 < hi:
        return window
    top = max(-lo, hi)
    return -top, top


def check_colour_map(name):
    """``name`` (None: none) as one of :data:`NAMES`, matplotlib's spelling "gray" taken as "grey"; one InputError
    (in the command line's words too) otherwise."""
    if name is None or isinstance(name, str) and name.replace("gray", "grey") in NAMES:
        return None if name is None else name.replace("gray", "grey")
    which = f"must be one of {', '.join(_FORWARD)}, or one of them reversed (_r: e.g. grey_r to show dark bright)"
    raise InputError(f"colour_map={name!r} {which}", cli=f"--colour-map {name} {which}")
