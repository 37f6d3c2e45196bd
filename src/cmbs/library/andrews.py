"""Andrews' squeezing mechanism: the seven-body benchmark of Schiehlen's *Multibody Systems
Handbook* (1990), in the relative angles of Hairer & Wanner's formulation (*Solving Ordinary
Differential Equations II*, 2nd ed., 1996, §VII.7, p. 530-536) and of the Test Set for IVP Solvers
(F. Mazzia, C. Magherini, Univ. of Bari, release 2.4, 2008, problem ``andrews``).

Seven rigid bodies (masses of grams to 70 g) in a plane without gravity: the crank (β) driven by
a constant motor torque ``mom`` = 0.033 N m, the coupler (Θ relative to the crank) whose end E is
held by three bodies at once — the triangle about B (γ), the pair about A through H (Φ, δ) and the
pair about A through K (Ω, ε) — and a spring of stiffness c0 = 4530 N/m from C to the triangle's
corner D.  Seven coordinates, six closure equations (E reached three ways), 1 DOF.  In 0.03 s
the crank accelerates to about 1100 rad/s: grams of mass, a stiff spring and a fast crank make
it a hard test of every formulation's accuracy.

With u = (β, Θ, γ, Φ, δ, Ω, ε) the equations of motion are M(u) ü + Aᵀλ = Q(u, u̇) with the
closures Φ(u) = 0 (Hairer & Wanner eq. VII.7.4-7.9; every constant below is theirs, in metres,
kilograms and seconds):

    E = (rr cos β - d cos(β+Θ), rr sin β - d sin(β+Θ))          (end of the coupler)
      = B + ss (sin γ, -cos γ)
      = A + zt (cos δ, sin δ) + e (sin(Φ+δ), -cos(Φ+δ))
      = A + u (sin ε, -cos ε) + zf (cos(Ω+ε), sin(Ω+ε)).

The potential V = ½ c0 (|CD| - l0)² - mom β (the motor torque is constant, so it derives from a
potential): T + V is conserved, which the energy check of every run uses.  Reference: the Test
Set's solution at t = 0.03 s (PSIDE at tolerance 1e-14), :data:`REFERENCE_AT_0_03`.
"""

from __future__ import annotations

import numpy as np

from cmbs.model.model import Model

#: Hairer & Wanner's constants (m, kg, kg m², N/m, N m).
CONSTANTS = dict(m1=0.04325, m2=0.00365, m3=0.02373, m4=0.00706, m5=0.07050, m6=0.00706, m7=0.05498,
                 i1=2.194e-6, i2=4.410e-7, i3=5.255e-6, i4=5.667e-7, i5=1.169e-5, i6=5.667e-7, i7=1.912e-5,
                 xa=-0.06934, ya=-0.00227, xb=-0.03635, yb=0.03273, xc=0.014, yc=0.072,
                 d=0.028, da=0.0115, e=0.02, ea=0.01421, rr=0.007, ra=0.00092,
                 ss=0.035, sa=0.01874, sb=0.01043, sc=0.018, sd=0.02, ta=0.02308, tb=0.00916,
                 u=0.04, ua=0.01228, ub=0.00449, zf=0.02, zt=0.04, fa=0.01421, c0=4530.0, l0=0.07785,
                 mom=0.033)

#: Consistent initial angles (Test Set), at rest.
INITIAL_ANGLES = (-0.0617138900142764496358948458001, 0.0, 0.455279819163070380255912382449,
                  0.222668390165885884674473185609, 0.487364979543842550225598953530,
                  -0.222668390165885884674473185609, 1.23054744454982119249735015568)

#: The Test Set's reference solution at t = 0.03 s: angles (rad), then angular velocities (rad/s).
REFERENCE_AT_0_03 = np.array([
    0.1581077119629904e2, -0.1575637105984298e2, 0.4082224013073101e-1, -0.5347301163226948,
    0.5244099658805304, 0.5347301163226948, 0.1048080741042263e1,
    0.1139920302151208e4, -0.1424379294994111e4, 0.1103291221937134e2, 0.1929337464421385e2,
    0.5735699284790808, -0.1929337464421385e2, 0.3231791658026955])


def andrews() -> Model:
    """Andrews' squeezing mechanism (see the module docstring): 7 angles, 6 closures, 1 DOF,
    started at rest from the Test Set's consistent angles."""
    import sympy

    from cmbs.model.equations import from_sympy

    k = {name: sympy.Rational(repr(value)) for name, value in CONSTANTS.items()}   # exact: T + V is shown conserved
    names = ("beta", "Theta", "gamma", "Phi", "delta", "Omega", "epsilon")
    beta, Theta, gamma, Phi, delta, Omega, epsilon = angles = sympy.symbols(names)
    beta_d, Theta_d, _, Phi_d, delta_d, Omega_d, epsilon_d = rates = sympy.symbols([f"{n}_d" for n in names])
    sin, cos = sympy.sin, sympy.cos
    e_ea, zf_fa = k["e"] - k["ea"], k["zf"] - k["fa"]

    mass = sympy.zeros(7, 7)
    mass[0, 0] = k["m1"] * k["ra"] ** 2 + k["m2"] * (k["rr"] ** 2 - 2 * k["da"] * k["rr"] * cos(Theta)
                                                     + k["da"] ** 2) + k["i1"] + k["i2"]
    mass[0, 1] = mass[1, 0] = k["m2"] * (k["da"] ** 2 - k["da"] * k["rr"] * cos(Theta)) + k["i2"]
    mass[1, 1] = k["m2"] * k["da"] ** 2 + k["i2"]
    mass[2, 2] = k["m3"] * (k["sa"] ** 2 + k["sb"] ** 2) + k["i3"]
    mass[3, 3] = k["m4"] * e_ea ** 2 + k["i4"]
    mass[3, 4] = mass[4, 3] = k["m4"] * (e_ea ** 2 + k["zt"] * e_ea * sin(Phi)) + k["i4"]
    mass[4, 4] = (k["m4"] * (k["zt"] ** 2 + 2 * k["zt"] * e_ea * sin(Phi) + e_ea ** 2)
                  + k["m5"] * (k["ta"] ** 2 + k["tb"] ** 2) + k["i4"] + k["i5"])
    mass[5, 5] = k["m6"] * zf_fa ** 2 + k["i6"]
    mass[5, 6] = mass[6, 5] = k["m6"] * (zf_fa ** 2 - k["u"] * zf_fa * sin(Omega)) + k["i6"]
    mass[6, 6] = (k["m6"] * (zf_fa ** 2 - 2 * k["u"] * zf_fa * sin(Omega) + k["u"] ** 2)
                  + k["m7"] * (k["ua"] ** 2 + k["ub"] ** 2) + k["i6"] + k["i7"])

    A, B, C = ((k["xa"], k["ya"]), (k["xb"], k["yb"]), (k["xc"], k["yc"]))
    D = (B[0] + k["sd"] * cos(gamma) + k["sc"] * sin(gamma), B[1] + k["sd"] * sin(gamma) - k["sc"] * cos(gamma))
    spring_length = sympy.sqrt((D[0] - C[0]) ** 2 + (D[1] - C[1]) ** 2)
    spring = -k["c0"] * (spring_length - k["l0"]) / spring_length      # force on D per metre of C->D
    forces = [
        k["mom"] - k["m2"] * k["da"] * k["rr"] * Theta_d * (Theta_d + 2 * beta_d) * sin(Theta),
        k["m2"] * k["da"] * k["rr"] * beta_d ** 2 * sin(Theta),
        spring * ((D[0] - C[0]) * (k["sc"] * cos(gamma) - k["sd"] * sin(gamma))
                  + (D[1] - C[1]) * (k["sd"] * cos(gamma) + k["sc"] * sin(gamma))),
        k["m4"] * k["zt"] * e_ea * delta_d ** 2 * cos(Phi),
        -k["m4"] * k["zt"] * e_ea * Phi_d * (Phi_d + 2 * delta_d) * cos(Phi),
        -k["m6"] * k["u"] * zf_fa * epsilon_d ** 2 * cos(Omega),
        k["m6"] * k["u"] * zf_fa * Omega_d * (Omega_d + 2 * epsilon_d) * cos(Omega),
    ]
    P = (k["rr"] * cos(beta), k["rr"] * sin(beta))
    E = (P[0] - k["d"] * cos(beta + Theta), P[1] - k["d"] * sin(beta + Theta))
    H = (A[0] + k["zt"] * cos(delta), A[1] + k["zt"] * sin(delta))
    K = (A[0] + k["u"] * sin(epsilon), A[1] - k["u"] * cos(epsilon))
    via_B = (B[0] + k["ss"] * sin(gamma), B[1] - k["ss"] * cos(gamma))
    via_H = (H[0] + k["e"] * sin(Phi + delta), H[1] - k["e"] * cos(Phi + delta))
    via_K = (K[0] + k["zf"] * cos(Omega + epsilon), K[1] + k["zf"] * sin(Omega + epsilon))
    closures = [E[0] - via_B[0], E[1] - via_B[1], E[0] - via_H[0], E[1] - via_H[1], E[0] - via_K[0], E[1] - via_K[1]]
    model = from_sympy(
        "andrews", coordinates=list(angles), velocities=list(rates), mass_matrix=mass, forces=forces,
        constraints=closures, drivers=[],
        constraint_names=["E via B x", "E via B z", "E via H x", "E via H z", "E via K x", "E via K z"],
        potential=k["c0"] / 2 * (spring_length - k["l0"]) ** 2 - k["mom"] * beta,
        points={"O": (0, 0), "P": P, "E": E, "A": A, "B": B, "C": C, "D": D, "H": H, "K": K},
        lines=[("O", "P"), ("P", "E"), ("B", "E"), ("B", "D"), ("E", "D"), ("A", "H"), ("H", "E"), ("A", "K"),
               ("K", "E"), ("C", "D")],
        q0=list(INITIAL_ANGLES), qd0=[0.0] * 7, coordinate_kinds=["angle"] * 7,
        description="Andrews' squeezing mechanism: 7 bodies (grams), spring 4530 N/m, motor torque 0.033 N m; "
                    "7 angles, 6 closures, 1 DOF",
        source="W. Schiehlen, Multibody Systems Handbook (1990); E. Hairer, G. Wanner, Solving ODEs II (1996) "
               "§VII.7; Test Set for IVP Solvers (Mazzia & Magherini 2008), problem 'andrews'")
    return model
