"""Integrators on generic vector fields and residuals (no mechanics imported here)."""


def __getattr__(name: str) -> object:
    """Submodules on first use (PEP 562): ``cmbs.integrate.NAME`` works after a plain ``import cmbs``."""
    from cmbs.lazy import submodule

    return submodule(__name__, name)
