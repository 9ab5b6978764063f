"""C text of numbers and tables: literals that round exactly, coefficient arrays, a state-space runner."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["CType", "DOUBLE", "FLOAT", "array_c", "state_space_c"]


@dataclass(frozen=True)
class CType:
    """A C floating-point type.

    Attributes
    ----------
    name : str
        The C type (``double``, ``float``).
    suffix : str
        Suffix of the functions in this type (``_f`` for float).
    lit : str
        Suffix of its literals (``f`` for float).
    dtype : type
        The numpy type of the coefficients.
    """

    name: str
    suffix: str
    lit: str
    dtype: type

    def num(self, v: float) -> str:
        """A literal that the compiler rounds to exactly ``dtype(v)``.

        Parameters
        ----------
        v : float
            The value.
        """
        if self.dtype is np.float32:
            text = f"{float(np.float32(v)):.9g}"
        else:
            text = f"{float(v):.17g}"
        if not any(c in text for c in ".eEn"):
            text += ".0"
        return text + self.lit


DOUBLE = CType("double", "", "", np.float64)
FLOAT = CType("float", "_f", "f", np.float32)


def array_c(ct: CType, name: str, values: np.ndarray) -> str:
    """A ``static const`` table of numbers.

    Parameters
    ----------
    ct : CType
        The type of the table.
    name : str
        Its C name.
    values : numpy.ndarray
        1-D, or rows of a 2-D array.
    """
    if values.ndim == 1:
        body = ",\n    ".join(", ".join(ct.num(v) for v in values[i:i + 4]) for i in range(0, values.size, 4))
        return f"static const {ct.name} {name}[{values.size}] = {{\n    {body}\n}};\n"
    rows = ",\n    ".join("{" + ", ".join(ct.num(v) for v in row) + "}" for row in values)
    return f"static const {ct.name} {name}[{values.shape[0]}][{values.shape[1]}] = {{\n    {rows}\n}};\n"


def state_space_c(prefix: str, name: str, what: str, ss: tuple[np.ndarray, ...]) -> str:
    """Tables and an in-place runner ``<prefix><name>_run(x, n)`` of one state-space map, from rest.

    Parameters
    ----------
    prefix : str
        Start of every C symbol.
    name : str
        The map's name in the symbols.
    what : str
        What the map is, for the comment.
    ss : tuple of numpy.ndarray
        ``(A, B, C, D)``, checked (:func:`~.entries.check_state_space`).
    """
    a, b, c, d = ss
    ns = b.size
    fn = f"{prefix}{name}_run"
    if ns == 0:
        return (f"\n/* {what}: a gain. */\nstatic void {fn}(double *x, size_t n)\n{{\n    size_t k;\n\n"
                f"    for (k = 0; k < n; ++k)\n        x[k] = {DOUBLE.num(d[0])} * x[k];\n}}\n")
    tables = "".join(array_c(DOUBLE, f"{prefix}{name}_{k}", v) for k, v in (("a", a), ("b", b), ("c", c)))
    return f"""
/* {what}: state space of {ns} states, run from rest over x[0..n) in place:
   y(k) = D u(k) + sum_i c_i s_i(k),  s_i(k + 1) = b_i u(k) + sum_j a_ij s_j(k)
   (what scipy.signal.dlsim computes, to rounding). */
{tables}
static void {fn}(double *x, size_t n)
{{
    double s[{ns}] = {{0.0}}, t[{ns}];
    size_t k, i, j;

    for (k = 0; k < n; ++k) {{
        const double u = x[k];
        double y = {DOUBLE.num(d[0])} * u;
        for (i = 0; i < {ns}; ++i)
            y = y + {prefix}{name}_c[i] * s[i];
        for (i = 0; i < {ns}; ++i) {{
            double v = {prefix}{name}_b[i] * u;
            for (j = 0; j < {ns}; ++j)
                v = v + {prefix}{name}_a[i][j] * s[j];
            t[i] = v;
        }}
        for (i = 0; i < {ns}; ++i)
            s[i] = t[i];
        x[k] = y;
    }}
}}
"""
