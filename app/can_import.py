"""``import can`` without python-can's MF4 logger: a second, not a second and 100 MB.

python-can 4 imports asammdf, and with it pandas, as soon as ``can`` is imported if asammdf
is installed (``can.io.mf4``, its MF4 log reader and writer; python-can issue #935, "Slow
library import time"): about 1 s and 100 MB in every process that talks CAN (the acquiring
one, the mock bench's, the GUI once it acquires). insitu reads and writes MDF files with
asammdf itself (:mod:`app.io.mdf`, loaded when such a file comes) and never logs CAN
traffic to MF4, so :func:`install` (called when :mod:`app` is imported) has ``can`` imported
with asammdf hidden: python-can then leaves its MF4 logger out, as when asammdf is not
installed, and asammdf stays importable for the rest of the process.

The hiding lasts while ``can`` itself is executed (a tenth of a second, once a process):
another thread importing asammdf for the first time in that window would be told it is not
installed (:func:`app.io.mdf.asammdf` says so in one line; opening the file again works).
"""

from __future__ import annotations

import importlib.abc
import importlib.machinery
import sys
from collections.abc import Sequence
from types import ModuleType
from typing import Any

__all__ = ["install"]

#: the module python-can imports at ``import can`` when installed, and what it pulls in
HIDDEN = "asammdf"


class _HidingLoader(importlib.abc.Loader):
    """``can``'s own loader, with :data:`HIDDEN` unimportable while it runs."""

    def __init__(self, inner: importlib.abc.Loader) -> None:
        self._inner = inner

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> ModuleType | None:
        return self._inner.create_module(spec)

    def exec_module(self, module: ModuleType) -> None:
        hide = HIDDEN not in sys.modules
        if hide:
            sys.modules[HIDDEN] = None  # type: ignore[assignment]  # "import asammdf" fails
        try:
            self._inner.exec_module(module)
        finally:
            if hide and HIDDEN in sys.modules and sys.modules[HIDDEN] is None:
                del sys.modules[HIDDEN]

    def __getattr__(self, name: str) -> Any:  # the rest of the loader's interface
        return getattr(self._inner, name)


class _CanFinder(importlib.abc.MetaPathFinder):
    """Finds ``can`` where the path finder does, once, and gives it :class:`_HidingLoader`."""

    def __init__(self) -> None:
        self.used = False

    def find_spec(self, fullname: str, path: Sequence[str] | None,
                  target: ModuleType | None = None) -> importlib.machinery.ModuleSpec | None:
        if fullname != "can" or self.used:
            return None
        self.used = True
        spec = importlib.machinery.PathFinder.find_spec(fullname, path, target)
        if spec is not None and spec.loader is not None:
            spec.loader = _HidingLoader(spec.loader)
        return spec


def install() -> None:
    """Have the process's first ``import can`` hide asammdf (nothing when ``can`` or
    asammdf is loaded already)."""
    if "can" in sys.modules or HIDDEN in sys.modules:
        return
    if not any(isinstance(f, _CanFinder) for f in sys.meta_path):
        sys.meta_path.insert(0, _CanFinder())
