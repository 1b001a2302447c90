"""The optional packages a file format needs, imported when a file of it is read or written."""

from __future__ import annotations

import importlib
from types import ModuleType

from processing.data import InputError


def optional_package(module: str, what: str, package: str, extra: str) -> ModuleType:
    """``module`` imported, or InputError in one line naming the ``pip install`` of insitu's
    ``extra`` that brings ``package`` (``what``: what needs it, e.g. "reading or writing
    TDMS files")."""
    try:
        return importlib.import_module(module)
    except ImportError as err:
        raise InputError(f"{what} needs {package}, an optional part of insitu: "
                         f"pip install 'insitu[{extra}]'") from err
