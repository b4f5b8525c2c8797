"""wmrid.model.urdf: the paper's physical parameters from a URDF, against Table 1 and independent computations."""

from __future__ import annotations

import dataclasses
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
from locations import DATA_DIR, ROOT_DIR
from scipy.spatial.transform import Rotation

from wmrid.core.errors import RobotFileError, UsageError
from wmrid.model import dynamics as model
from wmrid.model.robot import BUILTIN_ROBOTS, PAPER_CAD, PAPER_NOMINAL
from wmrid.model.urdf import load_robot_urdf, read_urdf, robot_from_urdf

PAPER_URDF = DATA_DIR / "paper_robot.urdf"
FRICTION = {"viscous_friction": (PAPER_CAD.F_v1, PAPER_CAD.F_v2), "coulomb_friction": (PAPER_CAD.F_d1, PAPER_CAD.F_d2)}
HALF_PI = "1.5707963267948966"


def paper_params(text: str | Path = PAPER_URDF, **kwargs):
    return robot_from_urdf(text, gear_ratio=PAPER_CAD.k_r, **{**FRICTION, **kwargs})


def assert_same_dynamics(p, ref=PAPER_CAD, rtol=1e-9):
    np.testing.assert_allclose(model.inertia_matrix(p), model.inertia_matrix(ref), rtol=rtol, atol=0)
    assert model.coriolis_coefficient(p) == pytest.approx(model.coriolis_coefficient(ref), rel=rtol, abs=0)


# --- the paper's robot -------------------------------------------------------------------------------------


def test_paper_urdf_gives_table1_dynamics():
    """Acceptance: M (Eqs. 10-12) and V_c (below Eq. 14) of the URDF equal those of the built-in CAD robot."""
    p = paper_params()
    assert_same_dynamics(p, BUILTIN_ROBOTS["paper"].cad)
    np.testing.assert_allclose(model.base_parameters(p), model.base_parameters(PAPER_CAD), rtol=1e-9)


@pytest.mark.parametrize("name", list(dataclasses.asdict(PAPER_CAD)))
def test_paper_urdf_each_parameter(name):
    # k_r and friction come from the arguments, everything else from the file.
    assert getattr(paper_params(), name) == pytest.approx(getattr(PAPER_CAD, name), rel=1e-12, abs=0)


def test_paper_urdf_joints_and_signs():
    m = read_urdf(PAPER_URDF, gear_ratio=100)
    assert m.name == "paper_robot"
    assert (m.right_wheel_joint, m.left_wheel_joint) == ("right_wheel_joint", "left_wheel_joint")
    assert m.rotor_joints == ("right_motor_rotor_joint", "left_motor_rotor_joint")
    # Right: axis z of a frame turned by roll -pi/2 -> +y; left: axis +y.  Both roll forward.
    assert m.wheel_signs == (1, 1)
    assert m.params.F_v1 == m.params.F_d2 == 0.0  # friction defaults to 0: a URDF has none


def _reordered(order) -> str:
    root = ET.parse(PAPER_URDF).getroot()
    children = list(root)
    for child in children:
        root.remove(child)
    for child in order(children):
        root.append(child)
    return ET.tostring(root, encoding="unicode")


def _wheels_swapped(children):
    names = [c.get("name") for c in children]
    i, j = names.index("right_wheel"), names.index("left_wheel")
    k, l = names.index("right_wheel_joint"), names.index("left_wheel_joint")
    out = list(children)
    out[i], out[j], out[k], out[l] = children[j], children[i], children[l], children[k]
    return out


@pytest.mark.parametrize("order", [_wheels_swapped, lambda c: c[::-1]], ids=["wheels swapped", "all reversed"])
def test_file_order_does_not_matter(order):
    text = _reordered(order)
    assert text.index('name="left_wheel"') < text.index('name="right_wheel"')
    m = read_urdf(text, gear_ratio=100, **FRICTION)
    assert (m.right_wheel_joint, m.left_wheel_joint) == ("right_wheel_joint", "left_wheel_joint")
    ref = paper_params()
    for name, value in dataclasses.asdict(m.params).items():
        assert value == pytest.approx(getattr(ref, name), rel=1e-13, abs=1e-15), name


def test_exporter_rounded_half_pi():
    # SolidWorks writes pi/2 as 1.5708 (3.7e-6 rad off): accepted, with a negligible effect.
    text = PAPER_URDF.read_text().replace(HALF_PI, "1.5708")
    assert_same_dynamics(paper_params(text), rtol=1e-9)


@pytest.mark.parametrize("how", ["fixed joints", "rotor_joints=()"])
def test_rotor_links_absent_is_equivalent(how):
    """Without rotor links their mass is platform mass: Eqs. (10)-(14) are unchanged once I_r is given."""
    text = PAPER_URDF.read_text()
    kwargs: dict = {"rotor_inertia": PAPER_CAD.I_r}
    if how == "fixed joints":
        text = text.replace('rotor_joint" type="continuous"', 'rotor_joint" type="fixed"')
    else:
        kwargs["rotor_joints"] = ()
    p = paper_params(text, **kwargs)
    assert (p.m_r, p.I_rm, p.c_x, p.c_y, p.I_r) == (0.0, 0.0, 0.0, 0.0, PAPER_CAD.I_r)
    assert p.m_p == pytest.approx(PAPER_CAD.m_p + 2 * PAPER_CAD.m_r, rel=1e-14)
    assert_same_dynamics(p)
    # Without rotor_inertia only k_r^2 I_r is missing, on the diagonal.
    del kwargs["rotor_inertia"]
    dm = model.inertia_matrix(PAPER_CAD) - model.inertia_matrix(paper_params(text, **kwargs))
    np.testing.assert_allclose(dm, np.eye(2) * PAPER_CAD.k_r**2 * PAPER_CAD.I_r, atol=1e-13)


def test_rotor_inertia_conflicts_with_rotor_links():
    with pytest.raises(UsageError, match="rotor links"):
        paper_params(rotor_inertia=1e-6)


def test_load_robot_urdf():
    robot = load_robot_urdf(PAPER_URDF, gear_ratio=100, **FRICTION, torque_constant=0.0105, efficiency=0.9)
    assert robot.name == "paper_robot"
    assert robot.cad == robot.nominal == paper_params()
    assert (robot.torque_constant, robot.efficiency) == (0.0105, 0.9)
    robot = load_robot_urdf(PAPER_URDF, gear_ratio=100, nominal=PAPER_NOMINAL, name="mine")
    assert (robot.name, robot.nominal) == ("mine", PAPER_NOMINAL)
    assert_same_dynamics(robot.cad)
    with pytest.raises(UsageError, match="efficiency"):
        load_robot_urdf(PAPER_URDF, gear_ratio=100, efficiency=1.5)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"gear_ratio": 0}, "gear_ratio"),
        ({"gear_ratio": 100, "viscous_friction": (0.1,)}, "viscous_friction"),
        ({"gear_ratio": 100, "coulomb_friction": (0.1, -1)}, "coulomb_friction"),
        ({"gear_ratio": 100, "wheel_radius": -0.1}, "wheel_radius"),
        ({"gear_ratio": 100, "wheel_joints": ("right_wheel_joint",)}, "wheel_joints"),
    ],
)
def test_bad_arguments(kwargs, match):
    with pytest.raises(UsageError, match=match):
        robot_from_urdf(PAPER_URDF, **kwargs)


# --- small URDFs -------------------------------------------------------------------------------------------


def inertial(mass=2.0, xyz="0 0 0", rpy="0 0 0", tensor=(0.01, 0, 0, 0.02, 0, 0.01)) -> str:
    attrs = " ".join(f'{k}="{v!r}"' for k, v in zip(("ixx", "ixy", "ixz", "iyy", "iyz", "izz"), tensor, strict=True))
    return f'<inertial><origin xyz="{xyz}" rpy="{rpy}"/><mass value="{mass!r}"/><inertia {attrs}/></inertial>'


def cylinder(radius=0.1, rpy=f"{HALF_PI} 0 0", tag="collision") -> str:
    return f'<{tag}><origin rpy="{rpy}"/><geometry><cylinder radius="{radius}" length="0.05"/></geometry></{tag}>'


def joint(name, child, y, kind="continuous", axis="0 1 0", x=0.0, parent="base_link") -> str:
    return (
        f'<joint name="{name}" type="{kind}"><origin xyz="{x} {y} 0" rpy="0 0 0"/><parent link="{parent}"/>'
        f'<child link="{child}"/><axis xyz="{axis}"/></joint>'
    )


BASE = f'<link name="base_link">{inertial(10.0, "0.05 0.01 0.1", tensor=(0.3, 0, 0, 0.4, 0, 0.5))}</link>'
PIECES = {
    "base": BASE,
    "right_link": f'<link name="right_wheel">{inertial()}{cylinder()}</link>',
    "right_joint": joint("right_wheel_joint", "right_wheel", -0.2),
    "left_link": f'<link name="left_wheel">{inertial()}{cylinder()}</link>',
    "left_joint": joint("left_wheel_joint", "left_wheel", 0.2),
    "extra": "",
}


def mini(**pieces: str) -> str:
    """A two-wheel robot: 10 kg platform at (0.05, 0.01), wheels at y = -+0.2 (r 0.1, 2 kg, I_w 0.02)."""
    return '<robot name="mini">' + "".join({**PIECES, **pieces}.values()) + "</robot>"


def test_mini():
    p = robot_from_urdf(mini(), gear_ratio=30)
    expected = dict(I_p=0.5, m_p=10.0, d_x=0.05, d_y=0.01, I_wm=0.01, I_w=0.02, m_w=2.0, a=0.2, r=0.1, b=0.2)
    assert {k: getattr(p, k) for k in expected} == pytest.approx(expected, rel=1e-14)
    assert (p.m_r, p.I_rm, p.I_r, p.c_x, p.c_y, p.k_r) == (0.0, 0.0, 0.0, 0.0, 0.0, 30.0)


@pytest.mark.parametrize("rpy", [(0.0, 0.0, 0.7), (0.4, 0.0, 0.0), (0.3, -0.5, 1.2), (-2.0, 1.1, 0.25)])
def test_inertial_rpy_rotates_the_tensor(rpy):
    """The <inertial> tensor is in a frame turned by rpy; I_p is izz of R I R^T (independent R from scipy)."""
    tensor = np.array([[0.3, 0.02, -0.05], [0.02, 0.45, 0.01], [-0.05, 0.01, 0.6]])
    flat = tuple(float(tensor[i, j]) for i, j in ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)))
    base = f'<link name="base_link">{inertial(10.0, "0.05 0.01 0.1", " ".join(map(repr, rpy)), flat)}</link>'
    rot = Rotation.from_euler("xyz", rpy).as_matrix()  # extrinsic x, y, z = URDF's Rz Ry Rx
    expected = (rot @ tensor @ rot.T)[2, 2]
    p = robot_from_urdf(mini(base=base), gear_ratio=30)
    assert p.I_p == pytest.approx(expected, rel=1e-13)
    assert (p.d_x, p.d_y) == pytest.approx((0.05, 0.01), rel=1e-14)  # rpy turns the tensor, not the origin


def test_rotated_wheel_and_platform_links_merge():
    # A wheel whose inertial is given about axes turned 90 deg about x (spin about local z), and a second
    # platform link on a yawed fixed joint: the parallel-axis theorem by hand.
    wheel = f'<link name="right_wheel">{inertial(rpy=f"{HALF_PI} 0 0", tensor=(0.01, 0, 0, 0.01, 0, 0.02))}'
    extra = (
        f'<link name="battery">{inertial(4.0, "0.1 0 0", tensor=(0.02, 0, 0, 0.05, 0, 0.06))}</link>'
        '<joint name="battery_joint" type="fixed"><origin xyz="0.1 -0.1 0" rpy="0 0 1.5707963267948966"/>'
        '<parent link="base_link"/><child link="battery"/></joint>'
    )
    p = robot_from_urdf(mini(right_link=wheel + cylinder() + "</link>", extra=extra), gear_ratio=30)
    assert (p.I_w, p.I_wm) == pytest.approx((0.02, 0.01), rel=1e-12)
    # battery centre of mass: (0.1, -0.1) + Rz(90) (0.1, 0) = (0.1, 0.0); its izz is unchanged by a yaw.
    m, cx, cy = 14.0, (10 * 0.05 + 4 * 0.1) / 14, (10 * 0.01 + 4 * 0.0) / 14
    ip = 0.5 + 10 * ((0.05 - cx) ** 2 + (0.01 - cy) ** 2) + 0.06 + 4 * ((0.1 - cx) ** 2 + (0.0 - cy) ** 2)
    assert (p.m_p, p.d_x, p.d_y, p.I_p) == pytest.approx((m, cx, cy, ip), rel=1e-12)


def test_a_is_the_wheel_centre_of_mass_and_b_the_joints():
    inboard = f'<link name="right_wheel">{inertial(xyz="0 0.003 0")}{cylinder()}</link>'
    left = f'<link name="left_wheel">{inertial(xyz="0 -0.003 0")}{cylinder()}</link>'
    p = robot_from_urdf(mini(right_link=inboard, left_link=left), gear_ratio=30)
    assert (p.a, p.b) == pytest.approx((0.197, 0.2), rel=1e-13)


def test_small_asymmetry_is_averaged_keeping_sums():
    right = f'<link name="right_wheel">{inertial(mass=2.02)}{cylinder()}</link>'
    left = f'<link name="left_wheel">{inertial(mass=2.0, xyz="0 0.001 0")}{cylinder()}</link>'
    p = robot_from_urdf(mini(right_link=right, left_link=left), gear_ratio=30)
    assert 2 * p.m_w == pytest.approx(4.02, rel=1e-14)
    assert 2 * p.m_w * p.a**2 == pytest.approx(2.02 * 0.2**2 + 2.0 * 0.201**2, rel=1e-14)


def test_wheel_signs_and_sphere_and_visual_radius():
    right = '<link name="right_wheel">' + inertial() + '<visual><geometry><sphere radius="0.12"/></geometry></visual>'
    left = f'<link name="left_wheel">{inertial()}{cylinder(0.12, tag="visual")}</link>'
    right_joint = joint("rj", "right_wheel", -0.2, axis="0 -1 0")
    text = mini(right_link=right + "</link>", left_link=left, right_joint=right_joint)
    m = read_urdf(text, gear_ratio=30)
    assert (m.wheel_signs, m.params.r, m.right_wheel_joint) == ((-1, 1), 0.12, "rj")


def test_wheel_radius_argument_for_mesh_wheels():
    mesh = '<visual><geometry><mesh filename="package://x/wheel.STL"/></geometry></visual>'
    text = mini(right_link=f'<link name="right_wheel">{inertial()}{mesh}</link>')
    assert robot_from_urdf(text, gear_ratio=30, wheel_radius=0.1).r == 0.1


def test_named_wheel_joints():
    extra = f'<link name="front_wheel">{inertial(0.3)}{cylinder(0.05)}</link>' + joint("front_joint", "front_wheel", 0)
    text = mini(extra=extra)
    with pytest.raises(RobotFileError, match=r"found 3 drive-wheel joints .*wheel_joints=\(right, left\)"):
        robot_from_urdf(text, gear_ratio=30)
    p = robot_from_urdf(text, gear_ratio=30, wheel_joints=("right_wheel_joint", "left_wheel_joint"))
    assert p.m_p == pytest.approx(10.3)  # the unnamed third wheel counts as platform
    with pytest.raises(RobotFileError, match="right one must have y < 0"):
        robot_from_urdf(text, gear_ratio=30, wheel_joints=("left_wheel_joint", "right_wheel_joint"))


def test_caster_on_continuous_joint_is_not_a_wheel():
    extra = (
        f'<link name="caster_wheel">{inertial(0.3)}{cylinder(0.05)}</link>'
        + joint("caster_wheel_joint", "caster_wheel", 0, x=0.3)
        + f'<link name="base_footprint"/>{joint("footprint", "base_link", 0, kind="fixed", parent="base_footprint")}'
    )
    p = robot_from_urdf(mini(extra=extra), gear_ratio=30)
    assert p.m_p == pytest.approx(10.3)


_ONE_ROTOR = f'<link name="right_rotor">{inertial(0.05)}</link>' + joint("right_rotor_joint", "right_rotor", -0.1)
_BAD = {
    "not XML": ("this is not XML", "not XML"),
    "broken XML": ('<robot name="x"><link name="a"></robot>', "not XML"),
    "not a robot": ("<sdf><model/></sdf>", "not <robot>"),
    "xacro": (
        '<robot xmlns:xacro="http://www.ros.org/wiki/xacro" name="r"><xacro:property name="r" value="1"/></robot>',
        "xacro",
    ),
    "no links": ('<robot name="r"/>', "no <link>"),
    "two roots": (mini(extra='<link name="stray"/>'), "2 root links"),
    "unknown link": (mini(extra=joint("j", "nowhere", 0, kind="fixed")), "'nowhere' is not defined"),
    "bad number": (mini(right_joint=joint("right_wheel_joint", "right_wheel", "0 a")), "expected 3 finite numbers"),
    "no base inertial": (mini(base='<link name="base_link"/>'), "no <inertial> with mass > 0 on 'base_link'"),
    "missing izz": (
        mini(base=BASE.replace('izz="0.5"', "")),
        "link 'base_link' <inertial> <inertia>: missing izz",
    ),
    "negative mass": (mini(base=BASE.replace('value="10.0"', 'value="-1"')), "mass"),
    "one wheel joint": (
        mini(left_joint=joint("left_wheel_joint", "left_wheel", 0.2, kind="fixed")),
        "found 1 drive-wheel joints",
    ),
    "three wheel joints": (
        mini(extra=f'<link name="w3">{inertial()}{cylinder()}</link>' + joint("w3_joint", "w3", 0.1)),
        "found 3 drive-wheel joints",
    ),
    "wheel without inertial": (
        mini(right_link=f'<link name="right_wheel">{cylinder()}</link>'),
        r"wheel link 'right_wheel' \(joint 'right_wheel_joint'\) has no <inertial>",
    ),
    "wheel without geometry": (
        mini(left_link=f'<link name="left_wheel">{inertial()}</link>'),
        "wheel link 'left_wheel' has no <collision> or <visual> cylinder or sphere.*wheel_radius",
    ),
    "misaligned cylinder": (
        mini(left_link=f'<link name="left_wheel">{inertial()}{cylinder(rpy="0 0 0")}</link>'),
        "wheel link 'left_wheel': its cylinder's axis",
    ),
    "same side": (mini(right_joint=joint("right_wheel_joint", "right_wheel", 0.1)), "cannot tell right from left"),
    "wheel at y = 0": (mini(right_joint=joint("right_wheel_joint", "right_wheel", 0)), "cannot tell right from left"),
    "axis along x": (
        mini(left_joint=joint("left_wheel_joint", "left_wheel", 0.2, axis="1 0 0")),
        "wheel joint 'left_wheel_joint': its axis .* not along y",
    ),
    "zero axis": (mini(left_joint=joint("left_wheel_joint", "left_wheel", 0.2, axis="0 0 0")), "zero vector"),
    "axle not along y": (
        mini(left_joint=joint("left_wheel_joint", "left_wheel", 0.2, x=0.1)),
        "the axle is not along y",
    ),
    "unbalanced wheel": (
        mini(left_link=f'<link name="left_wheel">{inertial(xyz="0.01 0 0")}{cylinder()}</link>'),
        "wheel link 'left_wheel': its centre of mass is 10 mm off its axle",
    ),
    "wheel masses differ": (
        mini(left_link=f'<link name="left_wheel">{inertial(mass=2.5)}{cylinder()}</link>'),
        "right and left wheel masses .* differ",
    ),
    "wheel radii differ": (
        mini(left_link=f'<link name="left_wheel">{inertial()}{cylinder(0.12)}</link>'),
        "right and left wheel radii differ",
    ),
    "one rotor": (mini(extra=_ONE_ROTOR), r"found 1 rotor joints.*rotor_joints=\(\)"),
    "rotor without inertial": (
        mini(
            extra='<link name="right_rotor"/><link name="left_rotor"/>'
            + joint("right_rotor_joint", "right_rotor", -0.1)
            + joint("left_rotor_joint", "left_rotor", 0.1)
        ),
        "rotor link 'right_rotor' .* has no <inertial>",
    ),
}


@pytest.mark.parametrize(("text", "match"), list(_BAD.values()), ids=list(_BAD))
def test_malformed_urdf(tmp_path, text, match):
    path = tmp_path / "robot.urdf"
    path.write_text(text)
    with pytest.raises(RobotFileError, match=match) as info:
        robot_from_urdf(path, gear_ratio=30)
    message = str(info.value)
    assert message.startswith(f"{path}: ")
    assert "\n" not in message


def test_missing_file_and_text_source(tmp_path):
    with pytest.raises(RobotFileError, match="no such URDF file"):
        robot_from_urdf(tmp_path / "nope.urdf", gear_ratio=30)
    with pytest.raises(RobotFileError, match=r"^<URDF text>: found 1 drive-wheel"):
        robot_from_urdf(mini(left_joint="", left_link=""), gear_ratio=30)


def test_cli_accepts_a_urdf_robot_with_its_gear_ratio():
    import json

    from cliutil import wmrid

    root = ROOT_DIR
    log = root / "sample_logs" / "paper_sinusoid.csv"
    urdf = root / "tests" / "data" / "paper_robot.urdf"
    args = ["identify", str(log), "--robot", str(urdf), "--format", "json"]
    proc = wmrid(*args, "--gear-ratio", "100")
    assert proc.returncode == 0, proc.stderr.decode()
    out = json.loads(proc.stdout)
    expected = model.named_base(model.base_parameters(BUILTIN_ROBOTS["paper"].cad))
    assert out["reference"]["m11"] == pytest.approx(expected["m11"], rel=1e-9)
    proc = wmrid(*args)
    assert proc.returncode == 2
    assert "--gear-ratio" in proc.stderr.decode()
