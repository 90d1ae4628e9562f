"""Pictures: off-screen rendering with PyVista (:mod:`.render`) and matplotlib plots (:mod:`.plots`)."""

from .._lazy import lazy_submodules as _lazy

_SUBMODULES = ('render', 'plots')
__getattr__, __dir__ = _lazy(__name__, globals(), _SUBMODULES)
