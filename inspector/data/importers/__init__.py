"""Other labs' evaluation outputs, read as sessions (in memory, or written by ``inspector import``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..._lazy import attach

__getattr__, __dir__, __all__ = attach(__name__, {
    "import_dreamzero": ".dreamzero_so101",
    "find_sources": ".dreamzero_so101",
    "load_in_memory": ".dreamzero_so101",
})

if TYPE_CHECKING:
    from .dreamzero_so101 import find_sources as find_sources
    from .dreamzero_so101 import import_dreamzero as import_dreamzero
    from .dreamzero_so101 import load_in_memory as load_in_memory
