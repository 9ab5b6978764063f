"""Optional packages, imported where they are used, with an error naming the extra to install.

The core install (``pip install ilcdob``) holds what every design, identification from CSV
and the paper's reproduction need. Three extras add what only some commands use:

============  ==========================================  ====================================
extra         packages                                     for
============  ==========================================  ====================================
``logs``      pyulog, pymavlink, pyarrow                   PX4 ULog and ArduPilot DataFlash
                                                           logs, Parquet files
``campaign``  dask, distributed, bokeh                     ``ilcdob campaign`` (a Dask cluster
                                                           and its dashboard)
``rotorpy``   rotorpy                                      the third-party multirotor simulator
============  ==========================================  ====================================

``ilcdob[all]`` installs all three.
"""

from __future__ import annotations

import importlib
from types import ModuleType

from .errors import IlcdobError

__all__ = ["MissingExtraError", "require"]


class MissingExtraError(IlcdobError, ImportError):
    """An optional package is not installed; the message names the extra that installs it."""


def require(module: str, extra: str, what: str) -> ModuleType:
    """Import ``module``, or say which extra of ilcdob installs it.

    Parameters
    ----------
    module : str
        The module to import (``"pyulog"``, ``"pyarrow.parquet"``, ...).
    extra : str
        The extra of ilcdob that installs it (``"logs"``, ``"campaign"``, ``"rotorpy"``).
    what : str
        What needs it, for the message ("reading a ULog file", ...).

    Returns
    -------
    module

    Raises
    ------
    MissingExtraError
        ``module`` cannot be imported.
    """
    try:
        return importlib.import_module(module)
    except ImportError as exc:
        package = module.split(".")[0]
        raise MissingExtraError(f"{what} needs the optional package {package}, which is not installed ({exc}); "
                                f"install it with: pip install 'ilcdob[{extra}]'") from None
