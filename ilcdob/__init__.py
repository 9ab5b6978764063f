"""ilcdob: disturbance observers plus learning among systems with mismatched dynamics.

Implements Modi, Chen, Liang, Zheng (2024), "Improving Disturbance Estimation and
Suppression via Learning among Systems with Mismatched Dynamics".

Signal convention (stated once, checked at every entry): a signal is a 1-D NumPy array of
samples on a uniform grid ``t = k * Ts``, ``k = 0..N-1``; positions in m, accelerations in
m/s^2, time in s.
"""

def _source_checkout_layout() -> None:
    """From a source checkout that is not installed (``python -m ilcdob`` in the repository root),
    map ilcdob.design / ilcdob.identification / ilcdob.validation onto the folders beside this
    one, as an installation does (pyproject.toml, ``[tool.setuptools.package-dir]``)."""
    import importlib.abc
    import importlib.util
    import sys
    from pathlib import Path

    here = Path(__file__).resolve().parent
    root = here.parent
    subs = ("design", "identification", "validation")
    if (here / "design").is_dir() or not (root / "pyproject.toml").is_file() \
            or not all((root / sub / "__init__.py").is_file() for sub in subs):
        return  # installed (or not this repository's layout): nothing to map

    class _Layout(importlib.abc.MetaPathFinder):
        def find_spec(self, name, path, target=None):  # noqa: D102 - the finder protocol
            sub = name[len(__name__) + 1:] if name.startswith(__name__ + ".") else ""
            if sub not in subs:
                return None
            return importlib.util.spec_from_file_location(name, root / sub / "__init__.py",
                                                          submodule_search_locations=[str(root / sub)])

    if not any(type(f).__name__ == "_Layout" for f in sys.meta_path):
        sys.meta_path.insert(0, _Layout())


_source_checkout_layout()

#: Public names -> the module that defines them, imported on first use (PEP 562), so that
#: ``import ilcdob`` (and the command line's start, which an early Ctrl-C may interrupt) stays light.
_EXPORTS = {
    **dict.fromkeys(("IlcdobError", "SpecError", "FleetError", "ModelFileError", "UnstableLoopError",
                     "SignalError", "NumericalError"), "errors"),
    **dict.fromkeys(("Fleet", "load_fleet", "default_fleet", "fleet_from_dict", "fleet_from_systems"), "fleet"),
    **dict.fromkeys(("add_system", "fleet_to_toml"), "fleet_io"),
    **dict.fromkeys(("IdentifiedModel", "load_model"), "identified"),
    **dict.fromkeys(("LoopSystem", "build_loop", "freqresp"), "loop"),
    **dict.fromkeys(("PlantSpec", "PIDSpec", "DOBSpec", "NoiseSpec", "SystemSpec", "IdentificationSpec",
                     "UncertaintySpec", "LimitSpec", "SensorSpec"), "specs"),
    # the workflow: flight logs -> models -> fleet -> filters
    "load_flight": "identification.loaders",
    **dict.fromkeys(("tfest", "FitOptions"), "identification.tfest"),
    "ModelStructure": "uncertainty",
    "design_pair": "design.pair",
    # designs and models as python-control objects and MATLAB files
    **dict.fromkeys(("LearningFilterTF", "filter_tf", "filters_tf", "load_design", "design_to_mat"),
                    "design.export.objects"),
    "model_to_mat": "matfile",
}


def __getattr__(name: str):
    """Import a public name (or a submodule) on first use."""
    import importlib

    if name in _EXPORTS:
        value = getattr(importlib.import_module(f"{__name__}.{_EXPORTS[name]}"), name)
        globals()[name] = value
        return value
    if not name.startswith("_"):
        try:
            return importlib.import_module(f"{__name__}.{name}")
        except ModuleNotFoundError as exc:
            if exc.name != f"{__name__}.{name}":
                raise
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted({*globals(), *_EXPORTS})


try:
    from importlib.metadata import PackageNotFoundError as _NotFound, version as _version

    __version__ = _version("ilcdob")
except _NotFound:  # a source checkout that is not installed
    __version__ = "unknown"

__all__ = list(_EXPORTS)
