"""The design methods as registered objects (design/methods/__init__.py): the registry is the one place that
knows a method by its name, every option a method claims is an option of ``ilcdob design``, and
no module outside the registry compares a method's name with a literal."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from ilcdob.app.cli import build_parser
from ilcdob.design.methods import DEFAULT_METHOD, DEFAULT_METHODS, GUARANTEED, METHODS, Method, method_named
from ilcdob.errors import SpecError

ROOT = Path(__file__).resolve().parent.parent


def test_the_registry_is_built_from_the_classes():
    assert list(METHODS) == ["closed-form", "fir", "norm-optimal", "robust", "robust-set"]
    assert all(isinstance(m, Method) and m.name == name for name, m in METHODS.items())
    assert len({type(m) for m in METHODS.values()}) == len(METHODS)
    assert GUARANTEED == ("robust", "robust-set") and DEFAULT_METHOD == "closed-form"
    assert set(DEFAULT_METHODS) <= set(METHODS)
    with pytest.raises(SpecError, match=r"`--method`: got 'fast', valid methods are \['closed-form', 'fir'"):
        method_named("fast", "--method")


def test_every_option_a_method_claims_is_an_option_of_design():
    parser = build_parser()
    design = parser._subparsers._group_actions[0].choices["design"]  # argparse keeps subparsers here
    known = {flag for action in design._actions for flag in action.option_strings}
    claimed = {option for m in METHODS.values() for option in m.cli_options}
    assert claimed and claimed <= known, sorted(claimed - known)


def _literal_names(node: ast.AST) -> set[str]:
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return {node.value}
    if isinstance(node, (ast.Tuple, ast.List, ast.Set)):
        return {e.value for e in node.elts if isinstance(e, ast.Constant) and isinstance(e.value, str)}
    return set()


def _is_method(node: ast.AST) -> bool:
    name = node.id if isinstance(node, ast.Name) else node.attr if isinstance(node, ast.Attribute) else ""
    return name == "method" or name.endswith("_method")


def _branches_on_method_names() -> list[str]:
    """``method == "fir"``, ``method in ("robust", ...)`` and the like, outside design/methods/__init__.py."""
    found = []
    for folder in ("ilcdob", "design", "identification", "validation"):
        for path in sorted((ROOT / folder).rglob("*.py")):
            if path == ROOT / "design" / "methods.py":
                continue
            for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
                if isinstance(node, ast.Compare):
                    sides = [node.left, *node.comparators]
                    literal = set().union(*(_literal_names(s) for s in sides))
                    if any(_is_method(s) for s in sides) and literal & set(METHODS):
                        found.append(f"{path.relative_to(ROOT)}:{node.lineno}")
    return found


def test_no_module_branches_on_a_method_name():
    assert _branches_on_method_names() == []


def test_the_branch_finder_sees_a_branch():
    fake = ROOT / "design" / "_methods_probe_never_committed.py"
    try:
        fake.write_text('def f(method, o):\n    return method == "fir" or o.method in ("robust",)\n')
        assert _branches_on_method_names() == ["design/_methods_probe_never_committed.py:2"] * 2  # both tests
    finally:
        fake.unlink()


def test_a_method_carries_its_options_and_design_pair_takes_eight_parameters():
    """The options travel with the method object: ``configured`` takes from shared settings what each
    method uses, and the design reads them from the method (no option objects side by side)."""
    import inspect

    import ilcdob
    from ilcdob.design.methods import FIR, ClosedForm, MethodSettings, NormOptimal, Robust, RobustSet
    from ilcdob.design.pair import design_pair
    from ilcdob.design.methods.robust import RobustOptions
    from ilcdob.design.methods.robust_set import RobustSetOptions

    assert len(inspect.signature(design_pair).parameters) <= 8
    settings = MethodSettings(n=120, rho=0.8, lifted=True)
    assert METHODS["norm-optimal"].configured(settings) == NormOptimal(n=120, lifted=True)
    assert METHODS["robust"].configured(settings) == Robust(RobustOptions(rho=0.8))
    assert METHODS["robust-set"].configured(settings) == RobustSet(RobustSetOptions(rho=0.8))
    assert METHODS["closed-form"].configured(settings) == ClosedForm()
    assert METHODS["fir"].configured(settings) == FIR()
    assert method_named(NormOptimal(n=7)) == NormOptimal(n=7)  # an object is its own method
    design = design_pair(ilcdob.default_fleet(), "UAV1", "UAV2", METHODS["norm-optimal"].configured(settings))
    assert design.method == "norm-optimal" and design.filters["n"] == 120 and design.lifted["L1"].shape == (120, 120)
