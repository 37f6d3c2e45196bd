"""The branch watch: a run that leaves its assembly branch ends as failed, not as a success.

Where a mechanism passes a singular configuration (the N-four-bar of IFToMM A02 whenever its
cranks are horizontal: the DOF jumps from 1 to N + 1), other assembly branches cross the one it
moves on.  The motion of ideal constraints with bounded applied forces stays on its branch: its
velocity is continuous and its accelerations bounded through the singular position, and the
velocity there selects the branch.  Moving onto another branch therefore takes an impulse, a
velocity change that no bounded force gives.  Near a singular position a formulation can make
one (an ill-conditioned solve turns a small velocity-constraint error into accelerations of
10⁴-10⁶ m/s² for a fraction of a millisecond); the run then goes on, on a valid assembly of
another branch, constraints satisfied and energy conserved, so that neither the constraint
errors nor the energy show it.  The watch looks at what every explicit loop has at each
accepted state: the time t, the velocities q̇ and the accelerations q̈.

**Why an impulse needs a singular Jacobian.**  A velocity change Δq̇ = M⁻¹Aᵀμ made by the
constraints between two admissible velocities (A q̇ = -Φ_t before and after, A nearly constant
over the short time) has A Δq̇ ≈ 0, hence Δq̇ᵀ M Δq̇ = μᵀ A Δq̇ ≈ 0: none unless A M⁻¹Aᵀ is
(nearly) singular.  A velocity jump at a regular configuration is thus an applied force's (a
stiff contact, an input) and no branch change: the watch fails a run only where the
constraint Jacobian is within :data:`NEAR_SINGULAR` of rank loss, σ_min / max(σ_max, 1) ≤ 0.1 for
A with each row divided by its norm at the first state (as the formulations' rank tests scale
it, so that a row that vanishes, the joint-coordinate slider-crank's at 90°, is seen; σ_min/σ_max
is the relative distance to the nearest rank-deficient matrix, Eckart-Young).  On A02 the ratio
is 0.37 θ, θ the crank angle from the horizontal: the gate holds within 15° of the passage.  It
is evaluated only when one of the two tests below finds a jump, so it costs nothing otherwise.

**The two tests** (the velocity change is measured in the Euclidean norm of q̇, against the
size |q̇| of the velocities at either end):

(a) *A jump inside one step*, between two accepted states a step h apart: the trapezoidal
    defect ‖q̇₁ - q̇₀ - h (q̈₀ + q̈₁)/2‖ > :data:`JUMP` · max(|q̇₀|, |q̇₁|).  For a smooth motion
    the defect is h³ ‖q⁽⁴⁾‖ / 12, about (h/τ)³/12 of |q̇| for a motion of time scale τ: it
    reaches half the speed only for a step of 1.8 τ, which resolves nothing.  A jump inside the
    step leaves the end accelerations ordinary and the defect about the jump.

(b) *A jump resolved into many small steps* (an adaptive loop follows the burst of
    accelerations): while each step changes the velocity by more than :data:`BURST` times
    what the reference acceleration a_ref gives in it, ‖Δq̇‖ > 10 a_ref h, a window stays open
    from the last ordinary state (t_w, q̇_w); the run has jumped when the change over the window
    exceeds what a_ref explains by JUMP of the speed:
    ‖q̇ - q̇_w‖ - 10 a_ref (t - t_w) > JUMP · max(|q̇_w|, |q̇|).

The reference a_ref is the largest |q̈| met so far, lagged: it follows a larger |q̈| no faster
than d(ln a_ref)/dt = :data:`FOLLOW` · a_ref / |q̇|, ten times the rate at which the motion's own
time scale τ = |q̇| / |q̈| (the time in which the accelerations change the velocity by its own
size) lets accelerations grow.  A physical motion's accelerations change on that scale, so
a_ref keeps up with them (on A02, from |q̈| = 1.7 m/s² at the start to the largest, 81 m/s², |q̈| / a_ref
stays below 1.6 at FOLLOW = 10, 3.3 at FOLLOW = 3); a burst of 10⁻⁴-10⁻² s cannot move it.

**Thresholds.**  JUMP = 0.5: a change of branch moves the velocity from one branch's tangent to
another's, by at least |q̇| sin φ for branches at an angle φ; half the speed catches branches 30°
apart or more (A02's: 55°; the jumps measured there are 1.3 to 1.9 times |q̇|).  BURST = 10:
physical accelerations stay within a small factor of the lagged reference (above), bursts reach
10² to 10⁵ times it.  Measured on A02 (N = 2, rk4 at 1 ms, rk45, dop853, every formulation):
runs that stay on the branch have defects up to 0.12 |q̇| and never open a window; the runs
that leave it are caught at the passage.  In the test suite (pendulums, slider-cranks through
their singular positions, four-bars, stiff springs, Baumgarte, penalty, the human model) no run
that stays on its branch meets an alarm; the natural slider-crank under projection and
Udwadia-Kalaba with the Moore-Penrose inverse, which switches branch at 1.99 s, now fails there,
and Andrews' squeezer under RK4 at 10 ms fails when |q̇| grows 10⁹ times in a step (reported as
a divergence: a jump after which |q̇| is :data:`DIVERGED` times what it was is no change of
branch, which keeps the kinetic energy).

The watch keeps its state in one float array (:func:`watch_array`), updated in place by
:func:`left_branch` at every accepted state (the first call starts it), in the compiled loops
and, through :class:`BranchWatch`, in the Python loop: the same code and numbers both ways.  A
run that fails keeps only the outputs up to the start of the jump, t ≤ ``watch[JUMP_FROM]``
(:func:`kept_records`), and says why (:func:`jump_message`).
"""

from __future__ import annotations

import math

import numpy as np

from cmbs.jit import interpreted, njit

#: The status a compiled loop returns when the watch ends the run (besides the formulations' and
#: the loops' own codes 0-7).
LEFT_BRANCH = 9
#: An unexplained velocity change of this fraction of |q̇| is a jump.
JUMP = 0.5
#: A step's accelerations explain at most this many times the reference acceleration.
BURST = 10.0
#: The reference acceleration follows larger ones at this many times the motion's own rate |q̈|/|q̇|.
FOLLOW = 10.0
#: σ_min / max(σ_max, 1) of the row-scaled constraint Jacobian at or below which a configuration is near-singular.
NEAR_SINGULAR = 0.1

# the watch array: scalars, then the previous state's q̇ and q̈ and the window's first q̇
REFERENCE, T_PREVIOUS, SPEED_PREVIOUS, OPEN, T_WINDOW, SPEED_WINDOW = 0, 1, 2, 3, 4, 5
JUMP_FROM, JUMP_TO, JUMP_SIZE, JUMP_SPEED, JUMP_REFERENCE, SINGULARITY, SPEED_FROM, SPEED_TO = range(6, 14)
SCALARS = 14
#: A jump after which |q̇| is this many times what it was is a divergence, not a change of branch
#: (which keeps the kinetic energy: the forces are bounded and the time short).
DIVERGED = 10.0


@njit(cache=True)
def watch_array(n, m):
    """The state of a watch over ``n`` coordinates and ``m`` constraints, not started (its first
    state starts it).  Plain numpy: called interpreted from Python (:func:`cmbs.jit.interpreted`),
    compiled from a batch of runs."""
    watch = np.zeros(SCALARS + 3 * n + m)
    watch[T_PREVIOUS] = np.nan
    return watch


@njit(cache=True)
def keep_row_scale(watch, n, A):
    """The row scale of the watch's Jacobians, 1/‖row i of A‖ at its first state (1 for a row of
    zeros), into the end of ``watch``."""
    start = SCALARS + 3 * n
    for i in range(A.shape[0]):
        total = 0.0
        for j in range(A.shape[1]):
            total += A[i, j] * A[i, j]
        watch[start + i] = 1.0 / math.sqrt(total) if total > 0.0 else 1.0


@njit(cache=True, inline="always")
def velocity_jump(watch, t, qd, qdd):
    """Tests (a) and (b) of the module at the accepted state (t, q̇, q̈), then the state becomes
    the previous one.  True when the velocity jumped: the interval (``JUMP_FROM``, ``JUMP_TO``),
    the change, the speeds and a_ref are left in ``watch``.  A non-finite state is passed over
    (the loops fail on it themselves); the first state starts the watch, and until a state with
    accelerations (a_ref > 0) there is nothing to judge a jump by.  One pass over the
    coordinates, squared norms compared (compiled into the loops)."""
    n = qd.shape[0]
    previous = SCALARS                                 # q̇ at SCALARS, q̈ at SCALARS + n, q̇_w after
    h = t - watch[T_PREVIOUS]
    speed, acceleration, defect, change = 0.0, 0.0, 0.0, 0.0
    for i in range(n):
        speed += qd[i] * qd[i]
        acceleration += qdd[i] * qdd[i]
        step = qd[i] - watch[previous + i]
        change += step * step
        gap = step - 0.5 * h * (watch[previous + n + i] + qdd[i])
        defect += gap * gap
    speed, acceleration = math.sqrt(speed), math.sqrt(acceleration)
    if not (math.isfinite(speed) and math.isfinite(acceleration)):
        return False
    jumped = False
    reference = watch[REFERENCE]
    if math.isfinite(h) and reference > 0.0:          # else no acceleration yet to judge by
        if defect > (JUMP * max(speed, watch[SPEED_PREVIOUS])) ** 2:                # (a)
            _note_jump(watch, watch[T_PREVIOUS], t, math.sqrt(change), watch[SPEED_PREVIOUS], speed, reference)
            jumped = True
        if change > (BURST * reference * h) ** 2:                                   # (b)
            jumped = _window_jump(watch, t, qd, speed, reference) or jumped
        else:
            watch[OPEN] = 0.0
        if speed > 0.0:
            watch[REFERENCE] = max(reference, min(acceleration, reference * (1.0 + FOLLOW * h * reference / speed)))
        else:
            watch[REFERENCE] = max(reference, acceleration)
    else:
        watch[REFERENCE] = max(reference, acceleration)
    watch[T_PREVIOUS], watch[SPEED_PREVIOUS] = t, speed
    for i in range(n):
        watch[previous + i] = qd[i]
        watch[previous + n + i] = qdd[i]
    return jumped


@njit(cache=True)
def _window_jump(watch, t, qd, speed, reference):
    """Test (b) at a step that changed the velocity by more than BURST a_ref h: the window opens at
    the previous state unless open; True when the change over it exceeds BURST a_ref (t - t_w) by
    JUMP of the speed."""
    n = qd.shape[0]
    previous, window = SCALARS, SCALARS + 2 * n
    if watch[OPEN] == 0.0:
        watch[OPEN], watch[T_WINDOW], watch[SPEED_WINDOW] = 1.0, watch[T_PREVIOUS], watch[SPEED_PREVIOUS]
        for i in range(n):
            watch[window + i] = watch[previous + i]
    total = 0.0
    for i in range(n):
        total += (qd[i] - watch[window + i]) ** 2
    total = math.sqrt(total)
    if total - BURST * reference * (t - watch[T_WINDOW]) > JUMP * max(speed, watch[SPEED_WINDOW]):
        _note_jump(watch, watch[T_WINDOW], t, total, watch[SPEED_WINDOW], speed, reference)
        return True
    return False


@njit(cache=True, inline="always")
def _note_jump(watch, start, end, change, speed_before, speed_after, reference):
    """Keep the jump over (start, end), the earlier start of tests (a) and (b) when both found one."""
    if watch[JUMP_TO] == end and watch[JUMP_FROM] <= start:
        return
    watch[JUMP_FROM], watch[JUMP_TO], watch[JUMP_SIZE] = start, end, change
    watch[JUMP_SPEED], watch[JUMP_REFERENCE] = max(speed_before, speed_after), reference
    watch[SPEED_FROM], watch[SPEED_TO] = speed_before, speed_after


@njit(cache=True)
def singularity(A, scale):
    """σ_min / max(σ_max, 1) of SA, S = diag(``scale``) (0 when A has more rows than columns; 1
    without rows), as the formulations' rank tests measure it (:func:`cmbs.dynamics.kkt.certify`):
    from the Gram matrix G = (SA)(SA)ᵀ, its Cholesky factor (a failed factorization: 0), inverse
    iteration for λ_min and the power method for λ_max (30 iterations each, from a fixed start;
    a Rayleigh quotient bounds λ_min from above, so the ratio errs towards regular).  Allocates
    its own work arrays."""
    m, n = A.shape
    if m == 0:
        return 1.0
    if m > n:
        return 0.0
    G = np.empty((m, m))
    for i in range(m):
        for k in range(i + 1):
            total = 0.0
            for j in range(n):
                total += A[i, j] * A[k, j]
            G[i, k] = total * scale[i] * scale[k]
            G[k, i] = G[i, k]
    L = np.zeros((m, m))
    for i in range(m):                          # Cholesky, G = L Lᵀ
        for k in range(i + 1):
            total = G[i, k]
            for j in range(k):
                total -= L[i, j] * L[k, j]
            if i == k:
                if total <= 1e-30 * max(G[i, i], 1.0):
                    return 0.0
                L[i, i] = math.sqrt(total)
            else:
                L[i, k] = total / L[k, k]
    x, y = np.empty(m), np.empty(m)
    for i in range(m):
        x[i] = 1.0 + 0.5 * math.sin(1.0 + 2.3 * i)
    largest = _power(G, x, y)
    for i in range(m):
        x[i] = 1.0 + 0.5 * math.sin(1.0 + 2.3 * i)
    smallest = 0.0
    for _ in range(30):                         # inverse iteration: solve G y = x by L, Lᵀ
        _normalize(x)
        for i in range(m):
            total = x[i]
            for j in range(i):
                total -= L[i, j] * y[j]
            y[i] = total / L[i, i]
        for i in range(m - 1, -1, -1):
            total = y[i]
            for j in range(i + 1, m):
                total -= L[j, i] * y[j]
            y[i] = total / L[i, i]
        product = 0.0
        for i in range(m):
            product += x[i] * y[i]
        smallest = 1.0 / product                # x unit: xᵀG⁻¹x → 1/λ_min
        for i in range(m):
            x[i] = y[i]
    return math.sqrt(max(smallest, 0.0)) / max(math.sqrt(largest), 1.0)


@njit(cache=True)
def _normalize(x):
    """x ← x / |x| in place (the power and inverse iterations' step)."""
    norm = 0.0
    for i in range(x.shape[0]):
        norm += x[i] * x[i]
    norm = math.sqrt(norm)
    for i in range(x.shape[0]):
        x[i] /= norm


@njit(cache=True)
def _power(G, x, y):
    """λ_max of the symmetric positive definite G by 30 steps of the power method from ``x``."""
    m = G.shape[0]
    largest = 0.0
    for _ in range(30):
        _normalize(x)
        product = 0.0
        for i in range(m):
            total = 0.0
            for j in range(m):
                total += G[i, j] * x[j]
            y[i] = total
            product += x[i] * total
        largest = product
        for i in range(m):
            x[i] = y[i]
    return largest


@njit(cache=True, inline="always")
def left_branch(watch, t, qd, qdd, A):
    """The watch at an accepted state (t, q̇, q̈) with constraint Jacobian ``A`` there (the first
    state's sets the row scale): True when the velocity jumped (:func:`velocity_jump`) at a
    near-singular configuration (:func:`singularity` ≤ :data:`NEAR_SINGULAR`, left in
    ``watch[SINGULARITY]``)."""
    n = qd.shape[0]
    if not math.isfinite(watch[T_PREVIOUS]):
        keep_row_scale(watch, n, A)
    if not velocity_jump(watch, t, qd, qdd):
        return False
    start = SCALARS + 3 * n
    watch[SINGULARITY] = singularity(A, watch[start:start + A.shape[0]])
    return watch[SINGULARITY] <= NEAR_SINGULAR


@njit(cache=True)
def kept_records(T, recorded, watch):
    """How many of the ``recorded`` output times T a run the watch ended keeps: those up to the
    start of the jump, ``watch[JUMP_FROM]`` (the outputs inside the jump's interval are not the
    mechanism's motion)."""
    start = watch[JUMP_FROM]
    while recorded > 0 and T[recorded - 1] > start + 1e-12 * max(1.0, abs(start)):
        recorded -= 1
    return recorded


#: What to try when an explicit integrator's run left its branch.
EXPLICIT_ADVICE = ("Try a smaller dt or rtol, drift projection to a tight tolerance (project=True, "
                   "projection_tolerance=1e-12; the CLI's --project --projection-tolerance 1e-12) or integrator "
                   "'generalized-alpha' (docs/formulations.md, \"Singular positions\")")
#: What to try when an implicit integrator's run left its branch (they have no drift projection).
IMPLICIT_ADVICE = ("Try a smaller dt; of the implicit integrators, generalized-alpha kept the branch at every step "
                   "tried on the N-four-bar (docs/formulations.md, \"Singular positions\")")


def jump_message(watch: np.ndarray, advice: str = EXPLICIT_ADVICE) -> str:
    """Why the watch ended a run: the jump, when and where, and what to try (``advice``); a
    divergence (|q̇| grown :data:`DIVERGED` times) is said to be one."""
    start, end, change, speed = watch[JUMP_FROM], watch[JUMP_TO], watch[JUMP_SIZE], watch[JUMP_SPEED]
    where = (f"between t={start:.6g} and t={end:.6g}, far more than the accelerations before explain "
             f"(reference |q̈| {watch[JUMP_REFERENCE]:.3g}), near a singular configuration (σ_min/σ_max of the "
             f"constraint Jacobian {watch[SINGULARITY]:.2g})")
    dropped = f"the outputs after t={start:.6g} are dropped"
    if watch[SPEED_TO] > DIVERGED * watch[SPEED_FROM]:
        return (f"the motion diverged: |q̇| grew from {watch[SPEED_FROM]:.3g} to {watch[SPEED_TO]:.3g} {where}; "
                f"{dropped}.  Try a smaller dt or rtol, or integrator 'generalized-alpha'")
    return (f"the velocity jumped by |Δq̇| = {change:.3g} ({change / speed:.2g} times |q̇|) {where}: the motion "
            f"left its assembly branch (a change of branch takes an impulse, which no bounded force gives); "
            f"{dropped}.  {advice}")


class BranchWatch:
    """The watch for the Python loop (:func:`cmbs.integrate.explicit.integrate`): called with each
    accepted state (t, y = (q, q̇), y' = (q̇, q̈)) of a run of ``model``, the first one first;
    returns None, or (the time from which outputs are dropped, the message) when the run left its
    branch.  The constraint Jacobian is evaluated only where the velocity jumped."""

    def __init__(self, model: object):
        self.model = model
        self.watch = interpreted(watch_array)(model.n, model.m)

    def __call__(self, t: float, y: np.ndarray, dy: np.ndarray) -> tuple[float, str] | None:
        n, m = self.model.n, self.model.m
        qd, qdd = np.ascontiguousarray(y[n:]), np.ascontiguousarray(dy[n:])
        if not np.isfinite(self.watch[T_PREVIOUS]):
            keep_row_scale(self.watch, n, self._jacobian(t, y))
        if not velocity_jump(self.watch, float(t), qd, qdd):
            return None
        start = SCALARS + 3 * n
        self.watch[SINGULARITY] = singularity(self._jacobian(t, y), self.watch[start:start + m])
        if self.watch[SINGULARITY] > NEAR_SINGULAR:
            return None
        return float(self.watch[JUMP_FROM]), jump_message(self.watch)

    def left_at(self, t: float, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> bool:
        """The watch at the accepted state (q, q̇, q̈) of an implicit integrator: True when the run
        left its branch there (the jump's message then from :func:`jump_message`)."""
        return self(t, np.concatenate((q, qd)), np.concatenate((qd, qdd))) is not None

    def _jacobian(self, t: float, y: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray(self.model.jacobian(y[:self.model.n], float(t)), dtype=float)
