"""PEP 562 submodule access for the package and its subpackages (as scipy does)."""

from __future__ import annotations

import importlib
from types import ModuleType
from typing import Callable


def lazy_submodules(package: str, namespace: dict, submodules: tuple[str, ...]) -> tuple[Callable, Callable]:
    """``(__getattr__, __dir__)`` for ``package``: each of ``submodules`` imported on first attribute access."""

    def __getattr__(name: str) -> ModuleType:
        if name in submodules:
            return importlib.import_module(f"{package}.{name}")
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    def __dir__() -> list[str]:
        return sorted(set(namespace) | set(submodules))

    return __getattr__, __dir__
