"""Joint reaction forces (cmbs.inverse.reactions): checked against statics of the whole
mechanism, Newton's third law at pins, and Newton-Euler for each segment with the accelerations
of the COM and the angular accelerations taken by finite differences of the point positions."""

import math

import numpy as np
import pytest

import cmbs
from helpers import library_four_bar_variant
from cmbs.errors import CmbsError
from cmbs.inverse import inverse_dynamics
from cmbs.inverse.reactions import joint_reaction_history, joint_reactions
from cmbs.library.mechanisms import slider_crank_joint

G = 9.81


def cross(a, b):
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def four_bar(coupler_com=(5.0, 0.0), driver="(pi/4) * sin(pi*t - pi/2)", name="four-bar-r"):
    """The library four-bar (A, B fixed; crank 2 m 1 kg, coupler 10 m 5 kg, rocker 6 m 3 kg), its
    coupler's COM optionally moved off the line of its points."""
    return library_four_bar_variant(name, coupler_com=coupler_com, driver=driver)


# segment: (i, j, mass, length, (along, across), I_G) — the numbers above, restated
FOUR_BAR = {"crank": ("A", "P1", 1.0, 2.0, (1.0, 0.0), 1 / 3),
            "coupler": ("P1", "P2", 5.0, 10.0, (5.0, 0.0), 5 * 100 / 12),
            "rocker": ("P2", "B", 3.0, 6.0, (3.0, 0.0), 9.0)}


def positions(model, motion):
    """{point: (k, 2)} from the trajectory's coordinates (fixed points from the model)."""
    points = np.array([model.point_positions(q) for q in motion.q])
    return {name: points[:, k] for k, name in enumerate(model.point_names)}


def com_of(r_i, r_j, length, com):
    d = r_j - r_i
    normal = np.stack([-d[..., 1], d[..., 0]], axis=-1)
    return r_i + com[0] / length * d + com[1] / length * normal


def test_static_four_bar_ground_reactions_balance_the_weight():
    model = four_bar(driver=-math.pi / 4, name="four-bar-held")
    ida = inverse_dynamics(model, np.array([0.0, 0.1]))
    q, lam = ida.motion.q[0], ida.motion.extras["lam"][0]
    assert np.abs(ida.motion.qdd[0]).max() < 1e-12
    result = joint_reactions(model, q, np.zeros(model.n), np.zeros(model.n), lam, 0.0)
    F_A, F_B = result["forces"][("crank", "A")], result["forces"][("rocker", "B")]
    torque = result["torques"]["alpha"]
    assert torque == pytest.approx(ida.force("alpha")[0], rel=1e-12)
    weight = 9.0 * G
    assert F_A[1] + F_B[1] == pytest.approx(weight, rel=1e-10)
    assert F_A[0] + F_B[0] == pytest.approx(0.0, abs=1e-10 * weight)
    assert abs(F_A[0]) > 1.0  # the ground pins do carry horizontal loads (a real split)
    # moments about A: the reaction at B, the weights at the COMs, the crank torque from the ground
    r = dict(zip(model.point_names, model.point_positions(q)))
    moment = cross(r["B"] - r["A"], F_B) + torque
    for i, j, mass, length, com, _ in FOUR_BAR.values():
        moment += cross(com_of(r[i], r[j], length, com) - r["A"], np.array([0.0, -mass * G]))
    assert moment == pytest.approx(0.0, abs=1e-10 * weight * 10)
    # the pins inside are in balance too
    F = result["forces"]
    np.testing.assert_allclose(F[("crank", "P1")] + F[("coupler", "P1")], 0.0, atol=1e-10 * weight)


def test_newtons_third_law_at_the_pins_of_the_driven_four_bar():
    model = cmbs.load("four-bar")
    ida = inverse_dynamics(model, np.linspace(0.0, 2.0, 101))
    F = joint_reaction_history(model, ida.motion)["forces"]
    scale = np.abs(F[("crank", "P1")]).max()
    assert scale > 10.0
    for a, b, point in (("crank", "coupler", "P1"), ("coupler", "rocker", "P2")):
        assert F[(a, point)].shape == (101, 2)
        np.testing.assert_allclose(F[(a, point)] + F[(b, point)], 0.0, atol=1e-11 * scale)


@pytest.mark.parametrize("coupler_com", [(5.0, 0.0), (4.0, 1.5)])
def test_newton_euler_of_each_segment(coupler_com):
    """m a_G = ΣF + m g and I_G α = Σ (r_P - r_G) × F + couple, with a_G and α from central
    differences (h = 1 ms) of the COM positions and segment angles computed from the points."""
    model = four_bar(coupler_com=coupler_com)
    h = 1e-3
    times = np.arange(0.0, 1.5 + h / 2, h)
    ida = inverse_dynamics(model, times)
    reactions = joint_reaction_history(model, ida.motion)
    F, couples = reactions["forces"], reactions["couples"]
    r = positions(model, ida.motion)
    segments = dict(FOUR_BAR, coupler=FOUR_BAR["coupler"][:4] + (coupler_com,) + FOUR_BAR["coupler"][5:])
    for name, (i, j, mass, length, com, inertia) in segments.items():
        r_G = com_of(r[i], r[j], length, com)
        a_G = (r_G[2:] - 2 * r_G[1:-1] + r_G[:-2]) / h**2
        d = r[j] - r[i]
        theta = np.unwrap(np.arctan2(d[:, 1], d[:, 0]))
        alpha = (theta[2:] - 2 * theta[1:-1] + theta[:-2]) / h**2
        force = F[(name, i)] + F[(name, j)] + np.array([0.0, -mass * G])
        scale = np.abs(F[(name, i)]).max()
        np.testing.assert_allclose(force[1:-1], mass * a_G, atol=1e-5 * scale)
        moment = cross(r[i] - r_G, F[(name, i)]) + cross(r[j] - r_G, F[(name, j)]) + couples[name]
        np.testing.assert_allclose(moment[1:-1], inertia * alpha, atol=1e-5 * scale * length)
        assert np.abs(mass * a_G).max() > 1e-3 * scale  # dynamics matter, not only statics
    np.testing.assert_allclose(couples["crank"], reactions["torques"]["alpha"], rtol=1e-12)
    np.testing.assert_allclose(couples["crank"], ida.force("alpha"), rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("block_mass", [0.0, 0.5])
def test_slider_force_is_normal_to_the_guide(block_mass):
    """Slider-crank (crank O-A, rod A-C 1 m 1 kg, C on the ground x axis) with gravity and the crank
    angle driven: the rod's reaction at C, and the guide's force on C by the block's Newton law
    (a_C by finite differences), are normal to the guide and agree with the slider row's force."""
    b = cmbs.NaturalModelBuilder("slider-crank-driven")
    theta = math.pi / 4
    b.add_point("O", 0.0, 0.0, fixed=True)
    b.add_point("A", math.cos(theta), math.sin(theta))
    b.add_point("C", 2 * math.cos(theta), 0.0, mass=block_mass)
    b.add_segment("crank", "O", "A", mass=1.0, com=(0.5, 0.0), inertia=1 / 12, length=1.0)
    b.add_segment("rod", "A", "C", mass=1.0, com=(0.5, 0.0), inertia=1 / 12, length=1.0)
    b.add_slider("guide", point="C", through=(0.0, 0.0), direction=(1.0, 0.0))
    b.add_angle("theta1", segment="crank")
    b.add_angle("theta2", from_segment="crank", to_segment="rod")
    b.add_driver("theta1", "pi/4 + 0.5*sin(3*t)")
    model = b.build()
    h = 1e-3
    ida = inverse_dynamics(model, np.arange(0.0, 1.0 + h / 2, h))
    reactions = joint_reaction_history(model, ida.motion)
    r_C = positions(model, ida.motion)["C"]
    a_C = (r_C[2:] - 2 * r_C[1:-1] + r_C[:-2]) / h**2
    on_rod = reactions["forces"][("rod", "C")][1:-1]
    # block: m a_C = m g + F_guide - F(rod, C)   (the rod pushes the block with -F(rod, C))
    guide = block_mass * a_C - block_mass * np.array([0.0, -G]) + on_rod
    scale = np.abs(on_rod).max()
    assert scale > 1.0
    np.testing.assert_allclose(guide[:, 0], 0.0, atol=1e-5 * scale)
    np.testing.assert_allclose(reactions["sliders"]["guide"][1:-1], guide, atol=1e-5 * scale)
    assert np.abs(guide[:, 1]).max() > 0.1 * scale
    # the relative angle theta2 has no torque on it: its row transmits no couple
    np.testing.assert_allclose(reactions["torques"]["theta2"], 0.0, atol=1e-10 * scale)


def test_errors():
    model = cmbs.load("four-bar")
    with pytest.raises(CmbsError, match="lam has shape"):
        joint_reactions(model, model.q0, model.qd0, np.zeros(model.n), np.zeros(2))
    motion = inverse_dynamics(model, np.linspace(0, 1, 3)).motion
    with pytest.raises(CmbsError, match="no 'lam'"):
        joint_reaction_history(model, cmbs.Trajectory(motion.t, motion.q, motion.qd, motion.qdd, motion.names))
    with pytest.raises(CmbsError, match="natural-coordinate"):
        joint_reactions(slider_crank_joint(), np.zeros(2), np.zeros(2), np.zeros(2), np.zeros(1))


def test_relative_angle_couples_act_on_both_segments():
    """Two-link arm, both joints driven; θ2 measured from the reversed first link (P1 → O) to the
    second, so the couple row's 'from' direction is a segment's points in reverse order.  Newton-
    Euler of each link (finite differences) holds with couple τ1 - τ2 on link 1 and τ2 on link 2."""
    b = cmbs.NaturalModelBuilder("two-link-driven")
    b.add_point("O", 0.0, 0.0, fixed=True)
    b.add_point("P1", 1.0, 0.0)
    b.add_point("P2", 1.0, -1.0)
    links = {"link1": ("O", "P1", 2.0, 1.0, (0.4, 0.1), 0.2), "link2": ("P1", "P2", 1.5, 1.0, (0.6, -0.2), 0.1)}
    for name, (i, j, mass, length, com, inertia) in links.items():
        b.add_segment(name, i, j, mass=mass, com=com, inertia=inertia, length=length)
    b.add_angle("theta1", segment="link1")
    b.add_angle("theta2", from_segment=("P1", "O"), to_segment="link2")
    b.add_driver("theta1", "0.3*sin(2*t)")
    b.add_driver("theta2", "1.2 + 0.8*cos(3*t)")
    model = b.build()
    h = 1e-3
    ida = inverse_dynamics(model, np.arange(0.0, 1.0 + h / 2, h))
    reactions = joint_reaction_history(model, ida.motion)
    F, couples, torques = reactions["forces"], reactions["couples"], reactions["torques"]
    np.testing.assert_allclose(torques["theta1"], ida.force("theta1"), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(torques["theta2"], ida.force("theta2"), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(couples["link1"], torques["theta1"] - torques["theta2"], atol=1e-10)
    np.testing.assert_allclose(couples["link2"], torques["theta2"], atol=1e-10)
    assert np.abs(torques["theta2"]).max() > 1.0
    np.testing.assert_allclose(F[("link1", "P1")] + F[("link2", "P1")], 0.0, atol=1e-10)
    r = positions(model, ida.motion)
    for name, (i, j, mass, length, com, inertia) in links.items():
        r_G = com_of(r[i], r[j], length, com)
        a_G = (r_G[2:] - 2 * r_G[1:-1] + r_G[:-2]) / h**2
        d = r[j] - r[i]
        theta = np.unwrap(np.arctan2(d[:, 1], d[:, 0]))
        alpha = (theta[2:] - 2 * theta[1:-1] + theta[:-2]) / h**2
        scale = np.abs(F[(name, i)]).max()
        force = F[(name, i)] + F[(name, j)] + np.array([0.0, -mass * G])
        np.testing.assert_allclose(force[1:-1], mass * a_G, atol=1e-5 * scale)
        moment = cross(r[i] - r_G, F[(name, i)]) + cross(r[j] - r_G, F[(name, j)]) + couples[name]
        np.testing.assert_allclose(moment[1:-1], inertia * alpha, atol=1e-5 * scale)


def test_locked_slider_block():
    """Slider-crank whose slider is a segment C-D kept parallel to the guide (``lock``): nothing but
    the block acts at D, so F(block, D) = 0; at the massless pin C the rod's and the block's
    reactions add up to the guide's normal force; and the block obeys Newton-Euler with the lock's
    couple."""
    b = cmbs.NaturalModelBuilder("slider-block")
    theta = math.pi / 4
    b.add_point("O", 0.0, 0.0, fixed=True)
    b.add_point("A", math.cos(theta), math.sin(theta))
    b.add_point("C", 2 * math.cos(theta), 0.0)
    b.add_point("D", 2 * math.cos(theta) + 0.4, 0.0)
    b.add_segment("crank", "O", "A", mass=1.0, com=(0.5, 0.0), inertia=1 / 12, length=1.0)
    b.add_segment("rod", "A", "C", mass=1.0, com=(0.5, 0.0), inertia=1 / 12, length=1.0)
    b.add_segment("block", "C", "D", mass=2.0, com=(0.3, 0.1), inertia=0.05, length=0.4)
    b.add_slider("guide", point="C", through=(0.0, 0.0), direction=(1.0, 0.0), lock="block")
    b.add_angle("theta1", segment="crank")
    b.add_driver("theta1", "pi/4 + 0.5*sin(3*t)")
    model = b.build()
    h = 1e-3
    ida = inverse_dynamics(model, np.arange(0.0, 1.0 + h / 2, h))
    reactions = joint_reaction_history(model, ida.motion)
    F = reactions["forces"]
    scale = np.abs(F[("rod", "C")]).max()
    assert scale > 1.0
    np.testing.assert_allclose(F[("block", "D")], 0.0, atol=1e-10 * scale)
    guide = reactions["sliders"]["guide"]
    np.testing.assert_allclose(guide[:, 0], 0.0, atol=1e-10 * scale)
    np.testing.assert_allclose(F[("rod", "C")] + F[("block", "C")], guide, atol=1e-10 * scale)
    couple = reactions["slider_couples"]["guide"]
    np.testing.assert_allclose(reactions["couples"]["block"], couple)
    assert np.abs(couple).max() > 0.1
    r = positions(model, ida.motion)
    r_G = com_of(r["C"], r["D"], 0.4, (0.3, 0.1))
    a_G = (r_G[2:] - 2 * r_G[1:-1] + r_G[:-2]) / h**2
    force = F[("block", "C")] + F[("block", "D")] + np.array([0.0, -2.0 * G])
    np.testing.assert_allclose(force[1:-1], 2.0 * a_G, atol=1e-5 * scale)
    # no rotation (α = 0): the moments about G of the forces and the lock's couple cancel
    moment = cross(r["C"] - r_G, F[("block", "C")]) + cross(r["D"] - r_G, F[("block", "D")]) + couple
    np.testing.assert_allclose(moment, 0.0, atol=1e-10 * scale)
