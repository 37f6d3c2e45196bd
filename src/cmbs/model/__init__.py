"""What a mechanism is: the frozen :class:`~cmbs.model.model.Model` and the builders that make it
(natural coordinates, joint coordinates, user equations, TOML files)."""
