"""The candidate effects live in :mod:`study.identify.effects` (identification with effects
belongs to ``study.identify``; the doctor uses it). This name stays for effects written against
it outside the package (``from study.doctor.effects import Effect``): the same classes and
functions."""
from ..identify.effects import *  # noqa: F401,F403
from ..identify.effects import __all__  # noqa: F401
