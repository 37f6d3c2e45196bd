"""Integrators: the generic ones on vector fields and residuals (:mod:`~cmbs.integrate.explicit`,
:mod:`~cmbs.integrate.implicit`), and the compiled loops that run a model's terms and a
formulation's solve at every stage (``compiled_rk4``, ``compiled_adaptive``, ``compiled_lanes``;
``variants`` runs a sweep's variants on them; :mod:`~cmbs.integrate.compiled_plan` says which run
takes which)."""


def __getattr__(name: str) -> object:
    """Submodules on first use (PEP 562): ``cmbs.integrate.NAME`` works after a plain ``import cmbs``."""
    from cmbs.lazy import submodule

    return submodule(__name__, name)
