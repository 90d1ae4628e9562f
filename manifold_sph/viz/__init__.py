"""Pictures: off-screen rendering with PyVista (:mod:`.render`) and matplotlib plots (:mod:`.plots`)."""

import importlib as _importlib

_SUBMODULES = ('render', 'plots')


def __getattr__(name: str):
    if name in _SUBMODULES:
        return _importlib.import_module(f"{__name__}.{name}")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_SUBMODULES))
