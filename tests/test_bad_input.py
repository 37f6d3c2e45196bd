"""Every kind of mistake in a model file gives one clear line naming the file, the entry and the
problem: through the CLI (exit status 2, one line on stderr, no traceback) and through
``cmbs.load`` (a :class:`cmbs.ModelError` with ``source``, ``entry`` and ``problem`` set)."""

import re
import textwrap

import pytest

import cmbs
from cmbs.cli import main

# A pendulum: fixed O, moving P, a rod "crank" between them and its absolute angle "th".
POINTS = """
[points]
O = { x = 0.0, z = 0.0, fixed = true }
P = { x = 1.0, z = 0.0 }
"""
CRANK = """
[segments.crank]
points = ["O", "P"]
mass = 1.0
com = [0.5, 0.0]
inertia = 0.1
"""
ANGLE = """
[angles.th]
segment = "crank"
"""
PENDULUM = POINTS + CRANK + ANGLE


def driver(expression=None, /, **keys):
    """A driver "d" on the pendulum's angle: ``expression`` (a string) and/or other keys (TOML values)."""
    lines = ["[drivers.d]", 'coordinate = "th"']
    if expression is not None:
        lines.append(f'expression = "{expression}"')
    lines += [f"{key} = {value}" for key, value in keys.items()]
    return PENDULUM + "\n".join(lines) + "\n"


FOUR_BAR_OPEN = """
[points]
A = { x = 0.0, z = 0.0, fixed = true }
B = { x = 10.0, z = 0.0, fixed = true }
P1 = { x = 0.0, z = 1.0 }
P2 = { x = 10.0, z = 1.0 }

# 1 + 2 + 1 < 10: the chain A-P1-P2-B cannot reach from A to B
[segments.crank]
points = ["A", "P1"]
length = 1.0
mass = 1.0
com = [0.5, 0.0]
inertia = 0.1

[segments.coupler]
points = ["P1", "P2"]
length = 2.0
mass = 1.0
com = [1.0, 0.0]
inertia = 0.1

[segments.rocker]
points = ["P2", "B"]
length = 1.0
mass = 1.0
com = [0.5, 0.0]
inertia = 0.1
"""

# (id, file text, entry as a regex or None for a file-level error, problem as a regex)
CASES = [
    # names
    ("unknown-point", POINTS + CRANK.replace('["O", "P"]', '["O", "Q"]'), r"segments\.crank",
     r"unknown point 'Q' \(points: O, P\)"),
    ("unknown-point-in-other-case", POINTS + CRANK.replace('["O", "P"]', '["O", "p"]'), r"segments\.crank",
     r"unknown point 'p' \(did you mean 'P'\?\) \(points: O, P\)"),
    ("unknown-point-in-spring", PENDULUM + '[springs.k]\npoints = ["P", "R"]\nstiffness = 1.0\n', r"springs\.k",
     r"unknown point 'R'"),
    ("unknown-segment-in-angle", POINTS + CRANK + '[angles.th]\nsegment = "crnak"\n', r"angles\.th",
     r"unknown segment 'crnak' \(did you mean 'crank'\?\) \(segments: crank\)"),
    ("duplicate-angle-and-distance", PENDULUM + '[distances.th]\npoints = ["O", "P"]\n', r"angles\.th",
     r"name 'th' is already a coordinate"),
    ("duplicate-point-coordinate", PENDULUM + '[distances."P.x"]\npoints = ["O", "P"]\n', r"distances\.P\.x",
     r"name 'P\.x' is already a coordinate"),
    ("toml-duplicate-table", PENDULUM + CRANK, None, r"not valid TOML: .*line"),
    ("toml-duplicate-key", POINTS + CRANK.replace("mass = 1.0", "mass = 1.0\nmass = 2.0"), None,
     r"not valid TOML: .*line"),
    # values
    ("negative-mass", POINTS + CRANK.replace("mass = 1.0", "mass = -1.0"), r"segments\.crank",
     r"mass must be >= 0, got -1\.0"),
    ("negative-point-mass", POINTS.replace("z = 0.0 }\n", "z = 0.0, mass = -0.5 }\n"), r"points\.P",
     r"mass must be >= 0"),
    ("negative-inertia", POINTS + CRANK.replace("inertia = 0.1", "inertia = -0.1"), r"segments\.crank",
     r"inertia must be >= 0, got -0\.1"),
    ("mass-without-com", POINTS + CRANK.replace("com = [0.5, 0.0]\n", ""), r"segments\.crank",
     r"needs 'com'"),
    ("negative-stiffness", PENDULUM + '[springs.k]\npoints = ["O", "P"]\nstiffness = -5.0\n', r"springs\.k",
     r"stiffness and damping must be >= 0"),
    ("spring-to-itself", PENDULUM + '[springs.k]\npoints = ["P", "P"]\nstiffness = 5.0\n', r"springs\.k",
     r"both ends are point 'P'"),
    ("spring-ends-coincide", PENDULUM.replace("[points]\n", "[points]\nQ = { x = 1.0, z = 0.0, fixed = true }\n")
     + '[springs.k]\npoints = ["Q", "P"]\nstiffness = 5.0\n', r"springs\.k", r"coincide"),
    ("zero-direction", PENDULUM + '[sliders.s]\npoint = "P"\nthrough = [0.0, 0.0]\ndirection = [0.0, 0.0]\n',
     r"sliders\.s", r"direction must not be the zero vector"),
    ("slider-two-lines", PENDULUM + '[sliders.s]\npoint = "P"\nline = ["O", "P"]\nsegment = "crank"\n',
     r"sliders\.s", r"give exactly one of 'line'"),
    # assembly and mass
    ("four-bar-cannot-close", FOUR_BAR_OPEN, r"segments\.(crank|coupler|rocker)",
     r"cannot be assembled: .*did not converge"),
    ("driver-out-of-reach", PENDULUM + '[drivers.reach]\ncoordinate = "P.x"\nexpression = "2 + t"\n',
     r"drivers\.reach", r"cannot be assembled at t = 0: drivers\.reach holds P\.x at 2 at t = 0, which the mechanism "
                         r"cannot reach"),
    ("point-without-mass", PENDULUM.replace("[points]\n", "[points]\nQ = { x = 2.0, z = 0.0 }\n")
     + '[segments.tip]\npoints = ["P", "Q"]\nmass = 0.0\n', r"points\.Q",
     r"mass matrix is not positive definite.*point\(s\) Q"),
    ("driven-half-a-turn-away", driver("pi"), r"angles\.th", r"half a turn away .*th = 3\.14159"),
    ("initial-half-a-turn-away", POINTS + CRANK + '[angles.th]\nsegment = "crank"\ninitial = 3.0\n', r"angles\.th",
     r"half a turn away"),
    # expressions
    ("unknown-function", driver("foo(t)"), r"drivers\.d\.expression", r"unknown name 'foo'"),
    ("unknown-function-in-torque", PENDULUM + '[torques.m]\nangle = "th"\ntorque = "sinh(t)"\n',
     r"torques\.m\.torque", r"unknown name 'sinh'"),
    ("missing-parenthesis", driver("sin(t"), r"drivers\.d\.expression", r"missing '\)' in expression 'sin\(t'"),
    ("extra-parenthesis", driver("2*t)"), r"drivers\.d\.expression", r"unexpected '\)'"),
    ("unbalanced-in-force", PENDULUM + '[forces.f]\npoint = "P"\nfx = "(1 + cos(t)"\n', r"forces\.f\.fx",
     r"missing '\)'"),
    ("stray-character", driver("2 $ t"), r"drivers\.d\.expression", r"unexpected character '\$' at position 2"),
    ("implicit-product", driver("2t"), r"drivers\.d\.expression", r"unexpected 't'"),
    ("empty-expression", driver(""), r"drivers\.d\.expression", r"empty expression"),
    ("division-by-zero-at-start", driver("1/t"), r"drivers\.d\.expression", r"not finite at t = 0: .*inf"),
    ("nan-at-start", driver("sqrt(0 - 1)"), r"drivers\.d\.expression", r"not finite at t = 0"),
    ("expression-not-string", driver(None, expression="true"), r"drivers\.d", r"expression must be a string"),
    # keys and types
    ("unknown-key", POINTS + CRANK.replace("mass = 1.0", "mas = 1.0"), r"segments\.crank",
     r"unknown key\(s\) 'mas' \(did you mean 'mass'\?\) \(allowed: points, mass, com, inertia, length\)"),
    ("unknown-key-in-model", "[model]\nnmae = 'x'\n" + PENDULUM, r"model",
     r"unknown key\(s\) 'nmae' \(did you mean 'name'\?\)"),
    ("unknown-key-far-from-any", POINTS + CRANK.replace("mass = 1.0", "mass = 1.0\ncolour = 1"), r"segments\.crank",
     r"unknown key\(s\) 'colour' \(allowed:"),
    ("missing-key", POINTS + CRANK.replace('points = ["O", "P"]\n', ""), r"segments\.crank",
     r"missing key\(s\) 'points'"),
    ("missing-coordinate-of-point", POINTS.replace("P = { x = 1.0, z = 0.0 }", "P = { x = 1.0 }") + CRANK,
     r"points\.P", r"missing key\(s\) 'z'"),
    ("missing-torque", PENDULUM + '[torques.m]\nangle = "th"\n', r"torques\.m", r"missing key\(s\) 'torque'"),
    ("string-mass", POINTS + CRANK.replace("mass = 1.0", 'mass = "1.0"'), r"segments\.crank",
     r"mass must be a number, got '1\.0'"),
    ("string-fixed", POINTS.replace("fixed = true", 'fixed = "yes"') + CRANK, r"points\.O",
     r"fixed must be true or false"),
    ("points-not-a-list", POINTS + CRANK.replace('["O", "P"]', '"O"'), r"segments\.crank",
     r"points must be a list of two names"),
    ("bad-gravity", "[model]\ngravity = -9.81\n" + PENDULUM, r"model", r"gravity must be a list of two finite numbers"),
    ("nan-gravity", "[model]\ngravity = [nan, -9.81]\n" + PENDULUM, r"model", r"two finite numbers, got \[nan"),
    ("infinite-position", POINTS.replace("x = 1.0", "x = inf") + CRANK, r"points\.P", r"x must be finite"),
    ("entry-not-a-table", POINTS.replace("P = { x = 1.0, z = 0.0 }", "P = 1.0") + CRANK, r"points\.P",
     r"expected a table of keys"),
    ("unknown-section", POINTS + CRANK.replace("[segments.crank]", "[segment.crank]"), None,
     r"unknown section\(s\) 'segment'"),
    # tables and files
    ("non-increasing-table", driver(None, table="{ t = [0.0, 1.0, 1.0, 2.0], value = [0.0, 0.1, 0.2, 0.3] }"),
     r"drivers\.d\.table", r"table times must be strictly increasing"),
    ("table-lengths-differ", driver(None, table='{ t = [0.0, 1.0, 2.0], value = [0.0, 0.1], '
                                                'interpolation = "linear" }'),
     r"drivers\.d\.table", r"3 times but 2 values"),
    ("spline-too-short", driver(None, table="{ t = [0.0, 1.0], value = [0.0, 0.1] }"), r"drivers\.d\.table",
     r"at least 4 samples"),
    ("bad-interpolation", driver(None, table="{ t = [0.0, 1.0], value = [0.0, 0.1] }", interpolation='"cubic"'),
     r"drivers\.d\.table", r"interpolation must be 'linear' or 'spline', got 'cubic'"),
    ("interpolation-twice", driver(None, table='{ t = [0.0, 1.0], value = [0.0, 0.1], interpolation = "linear" }',
                                   interpolation='"linear"'), r"drivers\.d\.table", r"give it once"),
    ("interpolation-of-expression", driver("t", interpolation='"linear"'), r"drivers\.d",
     r"'interpolation' applies to a 'table' or 'file' driver"),
    ("table-not-a-table", driver(None, table="3.0"), r"drivers\.d", r"table must be an inline table"),
    ("two-functions", driver("t", table="{ t = [0.0, 1.0], value = [0.0, 0.1] }"), r"drivers\.d",
     r"give exactly one of 'expression', 'table' or 'file'"),
    ("missing-csv", driver(None, file='"no-such-table.csv"'), r"drivers\.d\.file",
     r"file '.*no-such-table\.csv' not found"),
    # coordinates and angles
    ("unknown-driver-coordinate", PENDULUM + '[drivers.d]\ncoordinate = "P.y"\nexpression = "t"\n', r"drivers\.d",
     r"unknown coordinate 'P\.y' \(coordinates: P\.x, P\.z, th\)"),
    ("fixed-point-is-no-coordinate", PENDULUM + '[drivers.d]\ncoordinate = "O.x"\nexpression = "t"\n',
     r"drivers\.d", r"unknown coordinate 'O\.x'"),
    ("unknown-actuator-coordinate", PENDULUM + '[actuators.u]\ncoordinate = "theta"\n', r"actuators\.u",
     r"unknown coordinate 'theta'"),
    ("unknown-torque-angle", PENDULUM + '[torques.m]\nangle = "theta"\ntorque = 1.0\n', r"torques\.m",
     r"unknown angle 'theta' \(angles: th\)"),
    ("torque-on-distance", PENDULUM + '[distances.s]\npoints = ["O", "P"]\n[torques.m]\nangle = "s"\ntorque = 1.0\n',
     r"torques\.m", r"unknown angle 's'"),
]


def write(tmp_path, text, name="model.toml"):
    path = tmp_path / name
    path.write_text(textwrap.dedent(text))
    return path


def one_error_line(capsys):
    captured = capsys.readouterr()
    assert "Traceback" not in captured.err
    assert captured.out == ""
    lines = captured.err.splitlines()
    assert len(lines) == 1, captured.err
    assert lines[0].startswith("cmbs: error: ")
    return lines[0]


def expected_line(path, entry, problem):
    where = re.escape(str(path)) + (f": {entry}" if entry else "")
    return rf"cmbs: error: {where}: .*{problem}"


@pytest.mark.parametrize("text, entry, problem", [case[1:] for case in CASES], ids=[case[0] for case in CASES])
def test_cli_names_file_entry_and_problem(tmp_path, capsys, text, entry, problem):
    path = write(tmp_path, text)
    assert main(["describe", str(path)]) == 2
    line = one_error_line(capsys)
    assert re.fullmatch(expected_line(path, entry, problem) + ".*", line), line


@pytest.mark.parametrize("text, entry, problem", [case[1:] for case in CASES], ids=[case[0] for case in CASES])
def test_load_raises_model_error(tmp_path, text, entry, problem):
    path = write(tmp_path, text)
    with pytest.raises(cmbs.ModelError) as info:
        cmbs.load(path)
    error = info.value
    assert error.source == str(path)
    if entry is None:
        assert error.entry is None
    else:
        assert error.entry is not None and re.fullmatch(entry, error.entry), error.entry
    assert re.search(problem, error.problem), error.problem
    assert "\n" not in str(error)


def test_case_ids_are_unique():
    ids = [case[0] for case in CASES]
    assert len(ids) == len(set(ids))


def test_four_bar_that_closes_loads(tmp_path):
    """The open four-bar above fails only because of its lengths: with a closing coupler it loads."""
    path = write(tmp_path, FOUR_BAR_OPEN.replace("length = 2.0", "length = 10.0"))
    model = cmbs.load(path)
    assert cmbs.constraint_report(model, model.q0).dof == 1


# ---------------------------------------------------------------- files that are not model files
def test_nonexistent_model_file(tmp_path, capsys):
    path = tmp_path / "missing.toml"
    assert main(["describe", str(path)]) == 2
    assert one_error_line(capsys) == f"cmbs: error: {path}: no such model file"
    with pytest.raises(cmbs.ModelError, match="no such model file") as info:
        cmbs.load(path)
    assert info.value.source == str(path)


@pytest.mark.parametrize("name, content, problem", [
    ("notes.toml", "this is not a model, just words\n", "not valid TOML"),
    ("notes.txt", "[points\nO = 1\n", "not valid TOML"),
    ("image.toml", b"\x89PNG\r\n\x1a\n\xff\xfe\x00\x00", "not a text file"),
])
def test_file_that_is_not_toml(tmp_path, capsys, name, content, problem):
    path = tmp_path / name
    path.write_bytes(content if isinstance(content, bytes) else content.encode())
    assert main(["describe", str(path)]) == 2
    assert one_error_line(capsys).startswith(f"cmbs: error: {path}: {problem}")
    with pytest.raises(cmbs.ModelError, match=problem):
        cmbs.load(path)


def test_unknown_library_model(capsys):
    assert main(["describe", "four-barr"]) == 2
    line = one_error_line(capsys)
    assert "no library model or file 'four-barr'" in line and "four-bar" in line
    with pytest.raises(cmbs.ModelError, match="no library model or file 'four-barr' \\(did you mean 'four-bar'\\?\\)"):
        cmbs.load("four-barr")
    with pytest.raises(cmbs.ModelError, match="no library model or file 'zzz'; library models"):
        cmbs.load("zzz")                                     # nothing close: no suggestion


def test_misspelt_parameter_and_option_get_a_suggestion(capsys):
    assert main(["describe", "chain", "--param", "link=3"]) == 2
    assert "no parameter(s) link (did you mean 'links'?) (parameters: links=3, closed=False)" in one_error_line(capsys)
    with pytest.raises(cmbs.CmbsError, match="no option\\(s\\) omaga \\(did you mean 'omega'\\?\\)"):
        cmbs.formulation("baumgarte", omaga=20.0)


def test_misspelt_formulation_and_integrator_get_a_suggestion():
    with pytest.raises(cmbs.CmbsError, match="unknown formulation 'projektion' \\(did you mean 'projection'\\?\\)"):
        cmbs.formulation("projektion")
    with pytest.raises(cmbs.CmbsError, match="unknown integrator 'rk5' \\(did you mean 'rk45'\\?\\)"):
        cmbs.simulate("pendulum", t_end=1.0, integrator="rk5")


# ---------------------------------------------------------------- kinematics output paths
@pytest.mark.parametrize("options", [
    ["--out", "{tmp}/result.txt"],
    ["--out", "{tmp}/no-such-directory/result.npz"],
    ["--out", "{tmp}/result.csv", "--plot", "{tmp}/no-such-directory/figure.png"],
    ["--out", "{tmp}/result.csv", "--plot", "{tmp}/figure.jpg"],
], ids=["bad-extension", "missing-directory", "missing-plot-directory", "bad-plot-extension"])
def test_kinematics_bad_output_exits_2_and_writes_nothing(tmp_path, capsys, options):
    out = tmp_path / "out"
    out.mkdir()
    model = write(tmp_path, driver("0.5*sin(t)"), "driven.toml")
    arguments = [option.format(tmp=out) for option in options]
    assert main(["kinematics", str(model), "--t-end", "1", "--dt", "0.1", *arguments]) == 2
    line = one_error_line(capsys)
    assert arguments[-1] in line
    assert list(out.rglob("*")) == []


SINGULAR_FORCE = PENDULUM + """
[forces.f]
point = "P"
fz = "1/(t-0.5)"
"""
ROOT_FORCE = PENDULUM + """
[forces.f]
point = "P"
fz = "sqrt(1-t)"
"""
SINGULAR_DRIVER = PENDULUM + """
[drivers.spin]
coordinate = "th"
expression = "1/(t-0.5)"
"""


@pytest.mark.parametrize("options", [
    {"integrator": "rk4", "dt": 0.01},                        # the compiled RK4 loop
    {"integrator": "rk45", "dt": 0.01},                       # the compiled adaptive loop
    {"integrator": "rk4", "dt": 0.01, "compiled": False},     # the Python loop
    {"integrator": "trapezoidal", "dt": 0.01},                # matrix R in independent coordinates
])
def test_a_function_of_time_that_blows_up_mid_run_is_named(tmp_path, options):
    """1/(t - 0.5) is fine at t = 0 (so loading accepts it) and infinite at 0.5: the run stops there
    with a failed status whose message names the force, its expression and the time (it used to be
    a ZeroDivisionError raised from inside the compiled loop)."""
    path = tmp_path / "singular.toml"
    path.write_text(SINGULAR_FORCE)
    run = cmbs.simulate(cmbs.load(path), t_end=1.0, **options)
    assert run.info["status"] == "failed" and run.t[-1] < 0.5 + 1e-12
    assert "force f (fz) ('1/(t-0.5)') is not finite at t = 0.5" in run.info["message"], run.info["message"]


def test_a_square_root_of_a_negative_number_is_named(tmp_path):
    path = tmp_path / "root.toml"
    path.write_text(ROOT_FORCE)
    run = cmbs.simulate(cmbs.load(path), t_end=2.0, integrator="rk4", dt=0.01)
    assert run.info["status"] == "failed"
    assert "force f (fz) ('sqrt(1-t)') is not finite at t = 1" in run.info["message"], run.info["message"]


def test_kinematics_names_the_driver_that_blows_up(tmp_path, capsys):
    path = tmp_path / "driver.toml"
    path.write_text(SINGULAR_DRIVER)
    assert main(["kinematics", str(path), "--t-end", "1", "--dt", "0.1", "--out", str(tmp_path / "k.csv")]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "driver spin ('1/(t-0.5)') is not finite at t = 0.5" in err, err
    assert not (tmp_path / "k.csv").exists()


def test_a_folder_given_as_model_file_is_named_as_such(tmp_path, capsys):
    assert main(["describe", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "is a folder, not a model file" in err, err
