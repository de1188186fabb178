"""Package faces that load on first use: ``attach`` gives a package's ``__getattr__``, ``__dir__``
and ``__all__`` from a map of public name -> submodule (the lazy_loader convention).

A face that imported its submodules eagerly would make ``inspector info`` pay for rerun and viser
(and every spawned worker for the whole package): each command loads only what it touches. Each
package also imports the same names under ``if TYPE_CHECKING:``, so editors and type checkers see them.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from typing import Any


def attach(package: str, exports: dict[str, str]) -> tuple[Callable[[str], Any], Callable[[], list[str]], list[str]]:
    """(``__getattr__``, ``__dir__``, ``__all__``) for ``package`` exporting ``exports``.

    Args:
        package: the package's ``__name__``.
        exports: public name -> the submodule defining it, relative (``".session"``).
    """
    public = sorted(exports)

    def __getattr__(name: str) -> Any:
        if name not in exports:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(exports[name], package), name)
        globals_of_package = importlib.import_module(package).__dict__
        globals_of_package[name] = value  # later lookups skip __getattr__
        return value

    def __dir__() -> list[str]:
        return sorted(set(public) | set(importlib.import_module(package).__dict__))

    return __getattr__, __dir__, public
