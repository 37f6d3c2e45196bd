"""The N-four-bar of the IFToMM benchmark A02 in natural coordinates, and its exact motion.

M. González, D. Dopico, U. Lugrís, J. Cuadrado, "A benchmarking system for MBS simulation
software: problem standardization and performance measurement", Multibody Syst. Dyn. 16:179-190
(2006), problem A02 "N four-bar mechanism": 2N + 1 uniform bars of L = 1 m and m = 1 kg
(I_G = m L²/12); ground pivots A_i = (i, 0), i = 0..N; N + 1 vertical cranks A_i-B_i and N
horizontal couplers B_i-B_{i+1} at y = 1 at the start; ẋ(B0) = 1 m/s; gravity 9.81 m/s² along
-y; 20 s.  Whenever the cranks are horizontal all links are collinear and the mechanism's DOF
jumps from 1 to N + 1; the physical motion stays a chain of parallelograms, one degree of
freedom, the crank angle θ (from +x; B_i = A_i + L (cos θ, sin θ)).
"""

from __future__ import annotations

import math

import numpy as np

from cmbs.errors import CmbsError, ModelError
from cmbs.library.chain import MAX_LINKS
from cmbs.model.model import Model
from cmbs.model.natural import NaturalModelBuilder

BAR_LENGTH = 1.0      # L [m]
BAR_MASS = 1.0        # m [kg]
GRAVITY = 9.81        # g [m/s²], along -y
B0_SPEED = 1.0        # ẋ(B0) at t = 0 [m/s]

#: the largest N: the model then has 2N + 2 = 2,000 coordinates, as many as the longest library
#: chain (:data:`cmbs.library.chain.MAX_LINKS`; dense matrices grow as n², their factorizations as n³)
MAX_N = MAX_LINKS - 1


def n_four_bar(N: int = 2) -> Model:
    """Build IFToMM A02 with ``N`` ≥ 1 four-bar loops (N + 1 cranks, N couplers).

    Points A_i (ground, (i L, 0)) and B_i (crank tops, (i L, L) at the start); segments
    ``crank{i}`` A_i-B_i and ``coupler{i}`` B_i-B_{i+1}; coordinates (B_i.x, B_i.z), n = 2N + 2,
    m = 2N + 1 length constraints, 1 DOF at the start.  q̇0: every B_i moves at (ẋ, ż) = (1, 0)
    m/s (all cranks turn together at θ̇ = -1 rad/s, the parallelogram branch).
    """
    _check_loops(N)
    builder = NaturalModelBuilder(
        f"n-four-bar-N{N}", gravity=(0.0, -GRAVITY),
        description=f"IFToMM A02 N-four-bar, N = {N}: {N + 1} cranks and {N} couplers of {BAR_LENGTH:g} m, "
                    f"{BAR_MASS:g} kg; singular (DOF 1 -> {N + 1}) whenever the cranks are horizontal",
        source="M. González et al., Multibody Syst. Dyn. 16:179-190 (2006), IFToMM benchmark A02")
    for i in range(N + 1):
        builder.add_point(f"A{i}", i * BAR_LENGTH, 0.0, fixed=True)
        builder.add_point(f"B{i}", i * BAR_LENGTH, BAR_LENGTH)
    for i in range(N + 1):
        _add_bar(builder, f"crank{i}", f"A{i}", f"B{i}")
    for i in range(N):
        _add_bar(builder, f"coupler{i}", f"B{i}", f"B{i + 1}")
    model = builder.build()
    velocity = {"x": B0_SPEED, "z": 0.0}
    qd0 = [velocity[name.rpartition(".")[2]] for name in model.coordinate_names]
    return model.replace(qd0=qd0, parameters={**model.parameters, "N": N})


def _check_loops(N: object) -> None:
    """ModelError unless ``N`` is a whole number in 1..:data:`MAX_N`."""
    if isinstance(N, bool) or not isinstance(N, int) or N < 1:
        raise ModelError(f"N (the number of four-bar loops) must be a positive integer, got {N!r}",
                         entry="n-four-bar")
    if N > MAX_N:
        raise ModelError(f"N must be at most {MAX_N}, got {N} (2N + 2 coordinates; the dense matrices grow as "
                         "n² in memory and their factorizations as n³ in time)", entry="n-four-bar")


def _add_bar(builder: NaturalModelBuilder, name: str, i: str, j: str) -> None:
    """A uniform bar of the benchmark from point ``i`` to point ``j``."""
    builder.add_segment(name, i, j, mass=BAR_MASS, com=(BAR_LENGTH / 2, 0.0),
                        inertia=BAR_MASS * BAR_LENGTH ** 2 / 12, length=BAR_LENGTH)


def reduced_inertia(N: int) -> float:
    """I_eff = m L² ((N + 1)/3 + N): N + 1 cranks turning about their pivots (m L²/3 each) and N
    couplers translating at speed L θ̇ (m L² θ̇² / 2 each)."""
    return BAR_MASS * BAR_LENGTH ** 2 * ((N + 1) / 3 + N)


def reduced_gravity_moment(N: int) -> float:
    """C = m g L ((N + 1)/2 + N), V(θ) = C sin θ: crank centres at height (L/2) sin θ, couplers at L sin θ."""
    return BAR_MASS * GRAVITY * BAR_LENGTH * ((N + 1) / 2 + N)


def crank_angle(times: np.ndarray, N: int = 2, rtol: float = 1e-12) -> tuple[np.ndarray, np.ndarray]:
    """Crank angle θ [rad] (from +x) and rate θ̇ [rad/s] of :func:`n_four_bar` at ``times``: the
    exact motion on the parallelogram branch, a reference no singular position disturbs.

    On that branch every crank is at θ and every coupler horizontal, so (Lagrange's equation of
    the 1-DOF system, derived here; the reduction of González et al. 2006)::

        T = I_eff θ̇² / 2,   I_eff = m L² ((N + 1)/3 + N)
        V = C sin θ,         C     = m g L ((N + 1)/2 + N)
        I_eff θ̈ = -C cos θ,  θ(0) = π/2,  θ̇(0) = -ẋ(B0)/L = -1 rad/s

    I_eff is constant, so the ODE is regular where the mechanism is singular (θ = 0, π).
    Integrated by DOP853 (scipy) at ``rtol`` and atol = ``rtol``.
    """
    from scipy.integrate import solve_ivp

    _check_loops(N)
    times = np.asarray(times, dtype=float)
    if times.ndim != 1 or not times.size or not np.all(np.isfinite(times)) or times[0] < 0 \
            or np.any(np.diff(times) < 0):
        raise CmbsError(f"n-four-bar exact motion: times must be a non-empty, non-decreasing sequence of finite "
                        f"times >= 0, got {np.array2string(times, threshold=6)}")
    ratio = reduced_gravity_moment(N) / reduced_inertia(N)

    def field(_t: float, state: np.ndarray) -> list[float]:
        return [state[1], -ratio * math.cos(state[0])]

    solution = solve_ivp(field, (0.0, float(times[-1])), [math.pi / 2, -B0_SPEED / BAR_LENGTH], method="DOP853",
                         t_eval=times, rtol=rtol, atol=rtol)
    if not solution.success:
        raise CmbsError(f"n-four-bar exact motion: {solution.message}")
    return solution.y[0], solution.y[1]


def exact_b0(times: np.ndarray, N: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """Position and velocity of B0, each (len(times), 2) as (x, y), of :func:`n_four_bar` at
    ``times``: B0 = L (cos θ, sin θ), Ḃ0 = L θ̇ (-sin θ, cos θ) with θ from :func:`crank_angle`."""
    theta, omega = crank_angle(times, N)
    position = BAR_LENGTH * np.column_stack([np.cos(theta), np.sin(theta)])
    velocity = BAR_LENGTH * omega[:, None] * np.column_stack([-np.sin(theta), np.cos(theta)])
    return position, velocity
