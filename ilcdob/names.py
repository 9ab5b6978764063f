"""Names are data, never code or paths: the rule for system names, and one escape per target.

A system (vehicle) name follows one rule, checked wherever a fleet is read (fleet files,
``ilcdob fleet add``, :class:`~ilcdob.specs.SystemSpec` built in Python) by
:func:`check_name`:

* 1 to :data:`NAME_MAX_LENGTH` (64) characters;
* ASCII letters, digits, space and ``_ - . +``;
* starting with a letter or a digit, not ending with a space or ``.``.

So ``UAV1``, ``UAV 1``, ``Tarot-650`` and ``px4.heavy+cam`` are names; nothing a name can
hold ends a C comment, splices a line, opens an HTML tag, separates a path or a CSV field,
or reads differently on another terminal (ASCII only: no look-alike letters, no control or
direction characters).

The rule is the first line of defence. Every emitter escapes what it writes anyway, through
one helper per target, whatever the text's origin (a tampered ``filters.json``, say):

* :func:`c_identifier` -- a fragment of a C identifier (``filters.h``/``filters.c`` symbols);
* :func:`c_comment` -- text inside a C block comment: it can neither end the comment nor
  splice a line;
* :func:`html_text` -- text or attribute value of HTML (``ilcdob report``);
* :func:`file_name` -- one component of a file path (the folder of a vehicle);
* :func:`csv_field` -- one field of a CSV header row.

:func:`quoted` shows any text in a message: its ``repr``, shortened when long.
"""

from __future__ import annotations

import hashlib
import re
from html import escape

from .errors import SpecError

__all__ = ["NAME_MAX_LENGTH", "NAME_RULE", "check_name", "quoted", "c_identifier", "c_comment", "html_text",
           "file_name", "csv_field"]

#: Longest system name, characters.
NAME_MAX_LENGTH = 64
#: The rule of :func:`check_name`, as error messages state it.
NAME_RULE = (f"a system name is 1 to {NAME_MAX_LENGTH} characters: ASCII letters, digits, space and _ - . +, "
             "starting with a letter or a digit and not ending with a space or '.' (e.g. 'UAV1', 'Tarot-650')")

_NAME_CHARS = frozenset("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_-.+ ")
_ALNUM = frozenset("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789")
_QUOTE_LIMIT = 60
_WINDOWS_DEVICES = frozenset({"CON", "PRN", "AUX", "NUL", *(f"COM{i}" for i in range(1, 10)),
                              *(f"LPT{i}" for i in range(1, 10))})


def quoted(text: object, limit: int = _QUOTE_LIMIT) -> str:
    """``repr`` of ``text`` for a message, shortened to ``limit`` characters of text when longer.

    Parameters
    ----------
    text : object
        Any value; strings keep their quotes and show control characters escaped.
    limit : int
        Characters of a longer string shown before ``...``.

    Returns
    -------
    str
        ``repr(text)``, or ``repr(text[:limit]) + "... (N characters)"``.
    """
    if isinstance(text, str) and len(text) > limit:
        return f"{text[:limit]!r}... ({len(text)} characters)"
    shown = repr(text)
    return shown if len(shown) <= 4 * limit else shown[:4 * limit] + "..."


def _first_fault(name: str) -> str:
    """Why ``name`` breaks the rule (it does), in a few words."""
    if not name:
        return "it is empty"
    if len(name) > NAME_MAX_LENGTH:
        return f"it has {len(name)} characters, more than {NAME_MAX_LENGTH}"
    for i, ch in enumerate(name):
        if ch not in _NAME_CHARS:
            return f"character {ch!r} at position {i + 1} is not allowed"
    if name[0] not in _ALNUM:
        return f"it starts with {name[0]!r}"
    return f"it ends with {name[-1]!r}"


def check_name(name: object, where: str = "name") -> str:
    """Return ``name`` if it is a valid system name (module docstring), else raise :class:`SpecError`.

    Parameters
    ----------
    name : object
        The name given.
    where : str
        What it was given as, for the message (``name``, ``--name``).

    Returns
    -------
    str
        ``name``, unchanged.

    Raises
    ------
    SpecError
        Not a string, or a string breaking the rule; the message shows the value (shortened when
        long), says what is wrong with it and states :data:`NAME_RULE`.
    """
    if not isinstance(name, str):
        raise SpecError(f"`{where}`: got {type(name).__name__} {quoted(name)}, expected a text; {NAME_RULE}")
    valid = (0 < len(name) <= NAME_MAX_LENGTH and all(ch in _NAME_CHARS for ch in name)
             and name[0] in _ALNUM and name[-1] not in " .")
    if not valid:
        raise SpecError(f"`{where}`: got {quoted(name)}: {_first_fault(name)}; {NAME_RULE}. Rename the system")
    return name


def c_identifier(text: object) -> str:
    """``text`` as a fragment of a C identifier: every character other than an ASCII letter, digit
    or ``_`` becomes ``_``.

    Parameters
    ----------
    text : object
        Converted with ``str``.

    Returns
    -------
    str
        Only ``[A-Za-z0-9_]`` (a complete identifier must still not start with a digit).
    """
    return re.sub(r"[^A-Za-z0-9_]", "_", str(text))


def c_comment(text: object) -> str:
    """``text`` safe inside a C block comment ``/* ... */``.

    Every character outside printable ASCII (line breaks and other control characters
    included), every backslash (a line splice) and every ``?`` (``??/`` is the trigraph of a
    backslash) becomes ``_``; then ``*/`` becomes ``* /`` and ``/*`` becomes ``/ *``. The
    result is one line that can neither end the comment, nor open a nested one, nor splice
    the next line into it.

    Parameters
    ----------
    text : object
        Converted with ``str``.

    Returns
    -------
    str
        The text to put between ``/*`` and ``*/``.
    """
    plain = "".join(ch if " " <= ch <= "~" and ch not in "\\?" else "_" for ch in str(text))
    return plain.replace("*/", "* /").replace("/*", "/ *")


def html_text(value: object) -> str:
    """``value`` as HTML text or a quoted attribute value: ``& < > " '`` escaped, NUL replaced by
    U+FFFD (what a browser reads it as).

    Parameters
    ----------
    value : object
        Converted with ``str``.

    Returns
    -------
    str
        Text that renders as ``str(value)`` and opens no tag, entity or attribute.
    """
    return escape(str(value).replace("\x00", "\ufffd"), quote=True)


def file_name(text: object) -> str:
    """``text`` as one component of a file path, unchanged for every valid system name.

    Characters other than those of the name rule become ``_``, a leading character that is
    not a letter or digit (``.``, ``..``) and a trailing space or ``.`` too; a Windows device
    name (``CON``, ``NUL``, ...) gets a ``_`` appended; the result is at most
    :data:`NAME_MAX_LENGTH` characters. Whenever the text changes, the first 8 hex digits of
    its SHA-256 are appended, so two different texts do not share a file.

    Parameters
    ----------
    text : object
        Converted with ``str``.

    Returns
    -------
    str
        A non-empty name without path separators that is neither ``.`` nor ``..``.
    """
    raw = str(text)
    safe = "".join(ch if ch in _NAME_CHARS else "_" for ch in raw)[:NAME_MAX_LENGTH]
    if not safe or safe[0] not in _ALNUM:
        safe = "_" + safe[1:]
    if safe[-1] in " .":
        safe = safe[:-1] + "_"
    if safe.split(".")[0].upper() in _WINDOWS_DEVICES:
        safe += "_"
    if safe == raw:
        return safe
    digest = hashlib.sha256(raw.encode("utf-8", "surrogatepass")).hexdigest()[:8]
    return f"{safe[:NAME_MAX_LENGTH - 9]}-{digest}"


def csv_field(text: object) -> str:
    """``text`` as one field of a CSV header row (RFC 4180), unchanged for every valid system name.

    Control characters (line breaks included) become ``_``, so the header stays one line; a
    field holding ``,`` or ``"`` is quoted with ``"`` doubled; a field starting with ``=``,
    ``+``, ``-`` or ``@`` gets a leading ``'`` so that a spreadsheet does not run it as a
    formula.

    Parameters
    ----------
    text : object
        Converted with ``str``.

    Returns
    -------
    str
        The field as it goes between the commas.
    """
    plain = "".join("_" if ord(ch) < 0x20 or 0x7F <= ord(ch) < 0xA0 or ch in "\u2028\u2029" else ch
                    for ch in str(text))
    if plain[:1] in ("=", "+", "-", "@"):
        plain = "'" + plain
    if any(ch in plain for ch in ',"'):
        plain = '"' + plain.replace('"', '""') + '"'
    return plain
