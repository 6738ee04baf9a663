"""Named parameters of a system: the paper's symbols mapped to fields, read and replaced
functionally (for sweeps over designs, the CLI's ``--set`` and tuning).

Impact absorber: ``M, k, c, m, gap`` and the contact law's ``k1`` (= ``contact.stiffness``,
``kHz`` for Hertz laws), ``c1`` (= ``contact.damping``), ``eps``.
Friction absorber: ``m1, k1, c1, m2, k2, c2, N`` (= ``normal_force``) and the friction law's
fields (``mu``, ``mu_c``, ``mu_s``, ``v_s``, ``sigma0``, ``sigma1``, ``sigma2``, ``eps``).
Structural systems: ``<element name>.<field>`` (``tmd1.k``, ``friction1.N``).
Dotted paths (``contact.stiffness``) work too.
"""

from __future__ import annotations

import dataclasses

import equinox as eqx


def resolve(system, name: str) -> str:
    """Dotted field path of parameter ``name`` in ``system`` (``system.parameter_path``),
    checked to exist."""
    path = system.parameter_path(name)
    obj = system
    for part in path.split("."):
        ok = (part.isdigit() and isinstance(obj, tuple) and int(part) < len(obj)) or (
            not part.isdigit() and not part.startswith("_") and hasattr(obj, part))
        if not ok:
            raise ValueError(f"{type(system).__name__} has no parameter {name!r}; "
                             f"known: {', '.join(parameter_names(system))}")
        obj = obj[int(part)] if part.isdigit() else getattr(obj, part)
    return path


def _getter(path):
    def get(tree):
        for part in path.split("."):
            tree = tree[int(part)] if part.isdigit() else getattr(tree, part)
        return tree

    return get


def get_param(system, name):
    """The value of the parameter ``name`` of ``system`` (a JAX scalar, or array for a matrix
    field), in SI units.  ``name`` is one of
    [`parameter_names`][absorber_jax.parameter_names]: the paper's symbols (``"k"`` [N/m],
    ``"gap"`` [m], ``"k1"`` the contact stiffness, ``"N"`` the normal force [N], ...), a
    dotted field path (``"contact.stiffness"``) or, on a structural system,
    ``"<element>.<field>"`` (``"tmd1.k"``); an unknown name raises ``ValueError`` listing
    the known ones.

    ```python
    system, _ = aj.presets.impact("kelvin_voigt")
    aj.get_param(system, "k1")        # Array(400.), the contact stiffness [N/m] of Table 1
    ```
    """
    return _getter(resolve(system, name))(system)


# fields replace_params accepts that are model or numerical choices, not design parameters:
# a law's smoothing length, whether it pulls at separation, the exact stick-slip switch
SETTINGS = ("eps", "adhesive", "exact")


def parameter_names(system):
    """The design parameters of ``system`` by name, as
    [`replace_params`][absorber_jax.replace_params], [`get_param`][absorber_jax.get_param], sweeps
    (``params=``) and [`tune`][absorber_jax.tune] accept them: the paper's symbols (``k1``, ``c1``,
    ``m``, ``gap``, ``N``, ...) and their field names, element parameters as ``<element>.<field>``.
    Model settings (``eps``, ``adhesive``, ``exact``) are not listed, though
    [`replace_params`][absorber_jax.replace_params] accepts them too."""
    return [k for k in system.parameter_names() if k.rsplit(".", 1)[-1] not in SETTINGS]


def replace_params(system, values: dict, *, check=True):
    """``system`` with the named parameters replaced.  With ``check=True`` (concrete values)
    the result is rebuilt through the constructors, so bad values raise ``ValueError``;
    with ``check=False`` (inside jit/vmap/grad) it is a plain ``eqx.tree_at``."""
    paths = [resolve(system, k) for k in values]
    new = eqx.tree_at(lambda s: [_getter(p)(s) for p in paths], system,
                      [v for v in values.values()])
    return _rebuild(new) if check else new


def _rebuild(module):
    """Re-run a module's constructor (converters and checks) on its current fields."""
    if isinstance(module, tuple):
        return tuple(_rebuild(m) for m in module)
    if not isinstance(module, eqx.Module):
        return module
    kwargs = {}
    for f in dataclasses.fields(module):
        if not f.init:
            continue
        kwargs[f.name] = _rebuild(getattr(module, f.name))
    return type(module)(**kwargs)


with_params = replace_params
