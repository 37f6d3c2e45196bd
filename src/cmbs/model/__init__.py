"""What a mechanism is: the frozen :class:`~cmbs.model.model.Model` and the builders that make it
(natural coordinates, joint coordinates, user equations, TOML files)."""


def __getattr__(name: str) -> object:
    """Submodules on first use (PEP 562): ``cmbs.model.NAME`` works after a plain ``import cmbs``."""
    from cmbs.lazy import submodule

    return submodule(__name__, name)
