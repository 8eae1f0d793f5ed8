"""Eager check that an input is made of real numbers, before a cast to float could lose part
of it (the imaginary part of a complex number, True read as 1, digits parsed from text)."""
from __future__ import annotations

import numpy as np


def real_array(x, what: str, unit: str = "") -> np.ndarray:
    """``x`` as a float64 array. Raises ``ValueError`` naming ``what`` (and its ``unit``, e.g.
    "m") when ``x`` holds anything but integers and floats: complex numbers, booleans, text,
    objects, or lists of unequal lengths."""
    where = f" [{unit}]" if unit else ""
    try:
        a = np.asarray(x)
    except (TypeError, ValueError):
        raise ValueError(f"{what} must be an array of real numbers{where}; got {x!r:.80}") from None
    if a.dtype.kind not in "iuf":
        raise ValueError(f"{what} must be real numbers{where}; got dtype {a.dtype}")
    if holds_bool(x):                   # NumPy reads [True, 0.1] as [1.0, 0.1]
        raise ValueError(f"{what} must be real numbers{where}; got a boolean in {x!r:.80}")
    return a.astype(np.float64)


def kind(x) -> str:
    """NumPy's dtype kind of ``np.asarray(x)`` ("f", "i", "b", "U", ...), or "O" when ``x``
    cannot be made an array (lists of unequal lengths: NumPy raises on them)."""
    try:
        return np.asarray(x).dtype.kind
    except (TypeError, ValueError):
        return "O"


def holds_bool(x) -> bool:
    """Whether a (nested) list or tuple holds a Python or NumPy boolean."""
    if isinstance(x, (bool, np.bool_)):
        return True
    return isinstance(x, (list, tuple)) and any(holds_bool(v) for v in x)


def flag(x, what: str) -> bool:
    """``x`` as a bool when it is ``True`` or ``False`` (Python or NumPy); else ``TypeError``
    naming ``what``. A string such as "False" is true to Python and would silently switch the
    option on, and 0/1 are refused rather than guessed. A traced value (the switch passed as an
    argument of ``jax.jit``) is refused with the way to keep it static."""
    if not isinstance(x, (bool, np.bool_)):
        from .tracing import is_concrete
        if not is_concrete(x):
            raise TypeError(f"{what} is a switch that selects the program, but it arrived traced (an argument of "
                            f"jax.jit or vmap): pass it as a Python bool, static, e.g. "
                            f"jax.jit(jsq.squeeze, static_argnames=\"{what}\")")
        raise TypeError(f"{what}={x!r:.60} must be True or False")
    return bool(x)


def positive(x, what: str, unit: str = "") -> float:
    """``x`` as a float when it is one finite real number > 0; else ``ValueError`` naming
    ``what`` (and its ``unit``). Booleans, text, complex numbers and arrays of more than one
    value are refused rather than read as a number."""
    where = f" [{unit}]" if unit else ""
    try:
        a = np.asarray(x)
    except (TypeError, ValueError):
        a = np.asarray(None)
    if a.ndim != 0 or a.dtype.kind not in "iuf":
        raise ValueError(f"{what} must be one positive, finite number{where}; got {x!r:.80}")
    v = float(a)
    if not (np.isfinite(v) and v > 0):
        raise ValueError(f"{what} must be a positive, finite number{where}; got {v!r}")
    return v


def gib(nbytes) -> str:
    """A byte count in GiB for a message ("1.5 GiB"); a Python int too large for a float (a
    400-digit count from a scene file) reads as "inf GiB" rather than an OverflowError."""
    try:
        return f"{float(nbytes) / 1024 ** 3:.3g} GiB"
    except OverflowError:
        return "inf GiB"
