"""The quintic smoothstep shared by the force profiles, the postures and the walking pattern."""

from __future__ import annotations

import numpy as np


def smoothstep5(s):
    """s(x) = 10 x^3 - 15 x^4 + 6 x^5 of x clipped to [0, 1]: 0 -> 1 with zero first and
    second derivatives at both ends (a C2 blend).

    Args:
        s: the normalised time, a float or an array (any shape).

    Returns:
        A float for a Python float (the fast path of per-step callers), else an array of
        ``s``'s shape. Always computed as ``x*x*x*(10 + x*(-15 + 6*x))`` (Horner form), so
        every caller gets the same bits.
    """
    if type(s) is float:
        x = 0.0 if s < 0.0 else 1.0 if s > 1.0 else s
        return x * x * x * (10.0 + x * (-15.0 + 6.0 * x))
    x = np.clip(s, 0.0, 1.0)
    return x * x * x * (10.0 + x * (-15.0 + 6.0 * x))
