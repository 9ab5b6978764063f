"""Short text and HTML summaries of result objects, for the console and for notebooks.

Result classes define ``__repr__`` as one line naming what matters (``<TFEstimate fit 98.9 %
...>``) and ``_repr_html_`` as a small table, which Jupyter shows in place of the repr.
"""

from __future__ import annotations

from collections.abc import Sequence
from html import escape

__all__ = ["html_table", "fmt", "polynomial_text", "time_text"]


def fmt(value: object, digits: int = 4) -> str:
    """A number with ``digits`` significant digits (other values as ``str``).

    Parameters
    ----------
    value : object
        The value to show.
    digits : int
        Significant digits of floats.
    """
    if isinstance(value, bool) or value is None:
        return str(value)
    if isinstance(value, float):
        return f"{value:.{digits}g}"
    return str(value)


def html_table(title: str, header: Sequence[str], rows: Sequence[Sequence[object]]) -> str:
    """A small HTML table with a caption; cells are formatted with :func:`fmt` and escaped.

    Parameters
    ----------
    title : str
        Caption of the table.
    header : sequence of str
        Column names.
    rows : sequence of sequences
        Cell values, row by row.
    """
    head = "".join(f"<th>{escape(str(h))}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{escape(fmt(c))}</td>" for c in r) + "</tr>" for r in rows)
    return (f"<table><caption style='text-align:left'><b>{escape(title)}</b></caption>"
            f"<thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>")


def polynomial_text(c: Sequence[float], digits: int = 5) -> str:
    """A polynomial in ``s``, highest power first: ``[1, 2.8, 4]`` -> ``"1 s^2 + 2.8 s + 4"`` (zero terms left out,
    ``+ -`` written ``-``; ``"0"`` for none).

    Parameters
    ----------
    c : sequence of float
        Coefficients, highest power first.
    digits : int
        Significant digits of each coefficient.
    """
    n = len(c) - 1
    terms = []
    for i, v in enumerate(c):
        if v == 0:
            continue
        p = n - i
        terms.append(f"{v:.{digits}g}" + ("" if p == 0 else " s" if p == 1 else f" s^{p}"))
    return " + ".join(terms).replace("+ -", "- ") or "0"


def time_text(t: float) -> str:
    """A time stamp, s, to the microsecond and no further (``20.3218``, ``1710773350.123456``): what a message
    prints can be typed back as ``--start``/``--stop`` (a log's epoch clock shown as ``1.71077e+09`` cannot).

    Parameters
    ----------
    t : float
        The time, s.
    """
    text = f"{float(t):.6f}".rstrip("0").rstrip(".")
    return "0" if text in ("", "-0") else text
