"""Keywords that moved into method, objective and settings objects: still accepted, with a
``DeprecationWarning`` that shows the new form."""

from __future__ import annotations

import warnings


def moved(where: str, given: dict, form: str) -> None:
    """Warn that the keywords ``given`` of ``where`` now live in an object: ``form`` is the
    new spelling with ``{}`` where the keywords go, e.g. ``"integrator=aj.Integrator({})"``.
    """
    if not given:
        return
    args = ", ".join(f"{k}={v!r}" for k, v in given.items())
    warnings.warn(f"{where}({', '.join(f'{k}=...' for k in given)}) is deprecated: pass "
                  f"{form.format(args)}", DeprecationWarning, stacklevel=4)


def no_more(where: str, legacy: dict) -> None:
    """Raise the ``TypeError`` Python would for keywords that nothing took."""
    if legacy:
        raise TypeError(f"{where}() got an unexpected keyword argument "
                        f"{next(iter(legacy))!r}")
