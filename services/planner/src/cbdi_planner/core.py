"""Which search core runs: the compiled one (Rust, `cbdi_planner_core`) or the Python one.

The Python core is the reference: the compiled core does the same, in the same order, so
a search gives the same plans with either (`tests/planner/test_compiled_core.py`). The
environment variable `CBDI_SEARCH_CORE` selects: `compiled` (it must be built: `make
venv` builds it), `python`, or `auto` (the default: compiled when built, else Python).
"""

from __future__ import annotations

import os
from types import ModuleType

from cbdi.errors import CbdiError

__all__ = ["CORES", "compiled", "selected"]

CORES = ("auto", "compiled", "python")
VARIABLE = "CBDI_SEARCH_CORE"


class CoreError(CbdiError):
    """The search core asked for cannot run here."""

    code = "bad_search_core"


def selected(name: str | None = None) -> str:
    """Return the core `name` (default: the environment's) asks for; CoreError if unknown."""
    value = (name if name is not None else os.environ.get(VARIABLE, "auto")).strip().lower()
    if value not in CORES:
        raise CoreError(f"{VARIABLE}={value!r}: expected one of {', '.join(CORES)}")
    return value


def compiled(name: str | None = None) -> ModuleType | None:
    """Return the compiled core's module if the selection runs it, else None."""
    choice = selected(name)
    if choice == "python":
        return None
    try:
        import cbdi_planner_core
    except ImportError as exc:
        if choice == "compiled":
            raise CoreError(
                f"{VARIABLE}=compiled, but the compiled core is not built ({exc}): run "
                "`make venv` (it needs Rust's cargo: https://rustup.rs)"
            ) from None
        return None
    module: ModuleType = cbdi_planner_core
    return module
