"""The application layer stays thin: the argument parser is short and built from data, and no
function of ``ilcdob/app/`` grows beyond a screenful.

* ``ilcdob/app/cli.py`` holds at most :data:`MAX_CLI_LINES` lines: the options are declared in
  :mod:`ilcdob.app.options` and turned into argparse flags by one loop;
* no function or method of ``ilcdob/app/`` (nested ones included) spans more than
  :data:`MAX_FUNCTION_LINES` lines, docstring included (``end_lineno - lineno + 1`` of every
  ``FunctionDef``/``AsyncFunctionDef``, found with :mod:`ast`);
* an option several commands take is declared once (one :class:`~ilcdob.app.options.Flag`
  object that each of them names, not equal copies).
"""

from __future__ import annotations

import ast
from pathlib import Path

from ilcdob.app.options import COMMANDS, flags_of

APP = Path(__file__).resolve().parent.parent / "ilcdob" / "app"
#: Most lines of ilcdob/app/cli.py.
MAX_CLI_LINES = 250
#: Most lines of one function of ilcdob/app/.
MAX_FUNCTION_LINES = 80


def _long_functions(folder: Path, limit: int) -> list[str]:
    """``file:line name (N lines)`` of every function under ``folder`` longer than ``limit`` lines."""
    found = []
    for path in sorted(folder.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                lines = node.end_lineno - node.lineno + 1
                if lines > limit:
                    found.append(f"{path.relative_to(folder.parent.parent)}:{node.lineno} {node.name} ({lines} lines)")
    return found


def test_cli_is_short():
    lines = len((APP / "cli.py").read_text(encoding="utf-8").splitlines())
    assert lines <= MAX_CLI_LINES, (f"ilcdob/app/cli.py has {lines} lines, more than {MAX_CLI_LINES}: declare options "
                                    "in ilcdob/app/options.py")


def test_no_function_of_the_app_is_long():
    long = _long_functions(APP, MAX_FUNCTION_LINES)
    assert long == [], (f"functions of ilcdob/app/ over {MAX_FUNCTION_LINES} lines: " + "; ".join(long)
                        + " (split them into named steps)")


def test_the_length_check_sees_a_long_function(tmp_path):
    package = tmp_path / "pkg" / "app"
    package.mkdir(parents=True)
    body = "".join(f"    x{i} = {i}\n" for i in range(MAX_FUNCTION_LINES))
    (package / "m.py").write_text(f"class C:\n    def ok(self):\n        pass\n\n\ndef f():\n{body}"
                                  f"    def inner():\n{body.replace('    ', '        ')}")
    assert _long_functions(package, MAX_FUNCTION_LINES) == [
        f"pkg/app/m.py:6 f ({2 * MAX_FUNCTION_LINES + 2} lines)", f"pkg/app/m.py:{MAX_FUNCTION_LINES + 7} inner "
        f"({MAX_FUNCTION_LINES + 1} lines)"]


def test_a_shared_option_is_declared_once():
    objects: list[tuple[object, list[str]]] = []  # each distinct Flag object, with the commands naming it
    for command in COMMANDS:
        for flag in flags_of(command):
            for known, names in objects:
                if known is flag:
                    names.append(command.name)
                    break
            else:
                objects.append((flag, [command.name]))
    copies = [f"{a.names[0]} in {na} and {nb}" for i, (a, na) in enumerate(objects) for b, nb in objects[i + 1:]
              if a == b]
    assert copies == [], f"options declared more than once with the same fields (declare one Flag): {copies}"
