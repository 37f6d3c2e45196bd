"""N-link pendulum chain in natural coordinates (the chain of the benchmarks, benchmarks/bench_scaling.py).

N uniform slender rods (length 0.3 m, mass 1 kg, I_G = m l²/12) pinned at the origin, starting
at rest in a half circle with absolute link angles θ_k = -(k + ½)π/N; with ``closed`` the tip
is pinned to ground at its initial position (a closed chain, N - 2 DOF).
"""

from __future__ import annotations

import math

from cmbs.model.model import Model
from cmbs.model.natural import NaturalModelBuilder

LINK_LENGTH = 0.3
LINK_MASS = 1.0


#: the longest chain: 1,000 links build and describe in ~5 s and 0.4 GB; 5,000 take ~5 min and 5.6 GB
MAX_LINKS = 1000


def chain(links: int = 3, closed: bool = False) -> Model:
    """Build the chain; ``links`` ≥ 1 (≥ 3 when ``closed``)."""
    from cmbs.errors import ModelError

    if not isinstance(links, int) or links < 1:
        raise ModelError(f"links must be a positive integer, got {links!r}", entry="chain")
    if links > MAX_LINKS:
        raise ModelError(f"links must be at most {MAX_LINKS}, got {links} (the dense matrices and the rank "
                         "decomposition grow as n² in memory and n³ in time)", entry="chain")
    if closed and links < 3:
        raise ModelError(f"a closed chain needs at least 3 links, got {links}", entry="chain")
    builder = NaturalModelBuilder(
        f"chain{links}{'-closed' if closed else ''}",
        description=f"{links}-link pendulum chain{' with its tip pinned' if closed else ''}: "
                    f"rods {LINK_LENGTH} m, {LINK_MASS} kg, half-circle start",
        source="benchmark mechanism of cmbs (uniform slender rods; benchmarks/bench_scaling.py)")
    x = z = 0.0
    builder.add_point("P0", x, z, fixed=True)
    for k in range(links):
        theta = -(k + 0.5) * math.pi / links
        x, z = x + LINK_LENGTH * math.cos(theta), z + LINK_LENGTH * math.sin(theta)
        builder.add_point(f"P{k + 1}", x, z, fixed=closed and k == links - 1)
        builder.add_segment(f"link{k + 1}", f"P{k}", f"P{k + 1}", mass=LINK_MASS, com=(LINK_LENGTH / 2, 0.0),
                            inertia=LINK_MASS * LINK_LENGTH**2 / 12, length=LINK_LENGTH)
    model = builder.build()
    return model.replace(parameters={**model.parameters, "links": links, "closed": closed})
