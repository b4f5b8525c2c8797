"""The paper's physical parameters (Table 1) from a URDF, as exported from CAD (SolidWorks, Onshape, ...).

What is read, with every joint at position 0 and everything in the root link's frame (ROS REP 103:
x forward, y left, z up), relative to the axle midpoint O = midpoint of the two wheel joint origins:

* **Wheels**: the two ``continuous`` joints whose parent is the root link or a link fixed to it (joints
  or links named with "rotor", "caster"/"castor", or "motor" without "wheel" are not candidates), or
  the joints named by ``wheel_joints=(right, left)``.  The right wheel is the one whose joint origin has
  y < 0.  Each wheel is its link plus everything below it.  m_w is its mass, I_w its inertia about the
  joint axis (the <inertial> tensor rotated by the inertial's rpy and the link's pose, plus the parallel
  -axis term if its centre of mass is off the axle), I_wm its inertia about the vertical axis through
  its centre of mass, r the largest radius of a ``cylinder`` (axis along the joint axis) or ``sphere``
  among its <collision> geometries, else its <visual> ones (meshes are not read: pass ``wheel_radius``).
* **a and b**: b enters the rolling constraints (Eqs. 2-3, S(q) of Eq. 6), so it is where the wheel
  meets the ground: b = half the distance between the wheel joint origins (the wheel's mid-plane on its
  axle, where exporters put the joint).  a enters Eqs. (10)-(12) only through m_w a^2 in I, the
  parallel-axis term carrying each wheel's yaw inertia from its centre of mass O_w to O (the paper
  defines a as |O O_w|); the m b^2 term is the translational energy m v^2 with v = r (eta_1 + eta_2)/2,
  which is why it has b.  So a = horizontal distance from O to the wheel's centre of mass (its
  <inertial> origin).  Table 1's b = 0.23 m and a = 0.2286 m: the wheels' centres of mass sit 1.4 mm
  inboard of their treads.
* **Platform**: every other link (base link, casters, sensors, ...) merged as one rigid body: m_p its
  mass, (d_x, d_y) its centre of mass, I_p its inertia about the vertical through that centre of mass.
  A link on a moving joint that is neither wheel nor rotor (a caster swivel) counts at position 0.
* **Rotors** (optional): two joints, not ``fixed``, whose joint or child link name contains "rotor", or
  "motor" without "wheel", or those named by ``rotor_joints``: m_r, I_r (about the rotor's joint axis),
  I_rm (about the vertical), c_x and c_y = |y| of their centres of mass.  Without rotor links,
  m_r = I_rm = I_r = 0 and c_x = c_y = 0 except I_r = ``rotor_inertia``.  Nothing is lost: a rotor
  fixed in the CAD assembly is counted in the platform, and Eqs. (10)-(14) treat a rotor's mass and yaw
  inertia exactly as platform mass (symmetric rotors add nothing to m_p d_y, 2 m_r c_x to m_p d_x,
  2 (I_rm + m_r (c_x^2 + c_y^2)) to I either way).  Only the rotor's spin, k_r^2 I_r in M11 and M22, is
  missing, and only an argument can supply it.

What a URDF cannot give comes from arguments (later, CLI flags or a companion TOML): the gear ratio k_r
(``gear_ratio``, required), I_r when there are no rotor links (``rotor_inertia``), friction
(``viscous_friction``, ``coulomb_friction``, default 0) and r for mesh-only wheels (``wheel_radius``).

The paper's model has one m_w, I_w, I_wm, a, r for both wheels and one rotor set at (c_x, +-c_y); left
and right values differing by more than ``symmetry_tolerance`` (relative) are refused, smaller
differences are averaged so that 2 m_w, 2 m_w a^2 and the other sums stay exact.  Every problem raises
:class:`~wmrid.core.errors.RobotFileError` (the file, and the link or joint, and what to do, in one line);
conflicting arguments raise :class:`~wmrid.core.errors.UsageError`.  Only the standard library's
``xml.etree.ElementTree`` is used; xacro files must be expanded first (``xacro robot.urdf.xacro``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from wmrid.core.errors import RobotFileError, UsageError, option
from wmrid.model.robot import PhysicalParameters, Robot
from wmrid.model.urdf_tree import Body, Joint, Reader, load
from wmrid.runtime.atomic import register_input

_AXIS_TOLERANCE = 0.01  # rad: how far a wheel axis may lean from y (exporters round pi/2 to 1.5708)


_SIDE_EPSILON = 1e-6  # m: a wheel joint closer than this to y = 0 has no side


@dataclass(frozen=True)
class UrdfModel:
    """What :func:`read_urdf` found: the parameters and the joints that carry them.

    ``wheel_signs`` is +1 for a wheel whose positive joint velocity drives the robot forward (its axis
    points along +y), -1 when its axis points along -y; (right, left).
    """

    name: str | None  # the <robot name=...>
    params: PhysicalParameters
    right_wheel_joint: str
    left_wheel_joint: str
    wheel_signs: tuple[int, int]
    rotor_joints: tuple[str, str] | None  # (right, left), None when the file has no rotor links
    #: ((F_v1, F_v2), (F_d1, F_d2)) from the wheel joints' <dynamics damping= friction=> (a missing attribute is 0),
    #: None when neither wheel joint has a <dynamics> element (what ``wmrid export`` writes; CAD exporters rarely do)
    dynamics: tuple[tuple[float, float], tuple[float, float]] | None = None


def _is_rotor_name(name: str) -> bool:
    name = name.lower()
    return "rotor" in name or ("motor" in name and "wheel" not in name)


def _is_caster_name(name: str) -> bool:
    name = name.lower()
    return "caster" in name or "castor" in name


def _check_number(name: str, value: float, *, positive: bool = False) -> float:
    ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
    if not ok or value < 0 or (positive and value == 0):
        label = option(name) if name.isidentifier() else name  # a keyword (a flag on the command line), or a label
        raise UsageError(f"{label} must be a finite number {'> 0' if positive else '>= 0'}, got {value!r}")
    return float(value)


def _pair(name: str, value: Sequence[float]) -> tuple[float, float]:
    if len(value) != 2:
        raise UsageError(f"{name} must be (right, left), got {value!r}")
    return _check_number(f"{name}[0] (right)", value[0]), _check_number(f"{name}[1] (left)", value[1])


def _mean_checked(
    reader: Reader, what: str, right: float, left: float, tolerance: float, scale: float | None = None
) -> float:
    """(right + left) / 2 when they agree within ``tolerance`` of ``scale`` (default: the larger)."""
    ref = scale if scale is not None else max(abs(right), abs(left))
    if abs(right - left) > tolerance * ref:
        reader.fail(
            f"right and left {what} differ ({right:.6g} vs {left:.6g}, more than {tolerance:.0%}); the paper's "
            "model has one value for both sides: fix the CAD or raise symmetry_tolerance"
        )
    return 0.5 * (right + left)


def _named_joint(reader: Reader, name: str, role: str, kinds: tuple[str, ...]) -> Joint:
    joint = reader.joints.get(name)
    if joint is None:
        reader.fail(f"no joint named {name!r} (given as the {role}); joints: {', '.join(reader.joints)}")
    if joint.kind not in kinds:
        reader.fail(f"joint {name!r} (the {role}) is {joint.kind!r}; expected {' or '.join(kinds)}")
    return joint


def _sides(reader: Reader, joints: Sequence[Joint], what: str, given: bool) -> tuple[Joint, Joint]:
    """(right, left) by the sign of each joint origin's y in the root frame (x forward, y left)."""
    ys = [float(reader.pose[j.child][1][1]) for j in joints]
    names = f"{joints[0].name!r} (y = {ys[0]:+.4g} m) and {joints[1].name!r} (y = {ys[1]:+.4g} m)"
    if given:
        if not (ys[0] < -_SIDE_EPSILON and ys[1] > _SIDE_EPSILON):
            reader.fail(
                f"{what} joints given as (right, left) = {names}, but the right one must have y < 0 and the left "
                "y > 0 in the root frame (x forward, y left); swap them or fix the frame"
            )
        return joints[0], joints[1]
    if min(abs(y) for y in ys) <= _SIDE_EPSILON or (ys[0] > 0) == (ys[1] > 0):
        reader.fail(
            f"cannot tell right from left {what}: {names}; the right one must have y < 0 in the root frame "
            f"(x forward, y left): fix the frame, or name them with {what.rstrip('s')}_joints=(right, left)"
        )
    return (joints[0], joints[1]) if ys[0] < 0 else (joints[1], joints[0])


def _off_axis(reader: Reader, joint: Joint, point: np.ndarray) -> float:
    """Distance (m) from ``point`` (root frame) to the joint's axis line."""
    axis = reader.axis_in_root(joint)
    offset = point - reader.pose[joint.child][1]
    return float(np.linalg.norm(offset - float(offset @ axis) * axis))


def _spin_inertia(reader: Reader, joint: Joint, body: Body) -> float:
    """Inertia (kg m^2) about the joint axis line (parallel-axis term if the centre of mass is off it)."""
    axis = reader.axis_in_root(joint)
    return float(axis @ body.inertia @ axis) + body.mass * _off_axis(reader, joint, body.com) ** 2


def _wheel_radius(reader: Reader, link: str, axis: np.ndarray) -> float | None:
    """Largest cylinder (axis along the wheel axis) or sphere radius of <collision>, else <visual>."""
    rot_l = reader.pose[link][0]
    misaligned = False
    for tag in ("collision", "visual"):
        radii = []
        for el in reader.links[link].findall(tag):
            geometry = el.find("geometry")
            if geometry is None:
                continue
            rot_g, _ = reader.origin(el, f"link {link!r} <{tag}>")
            for shape in ("cylinder", "sphere"):
                g = geometry.find(shape)
                if g is None:
                    continue
                radius = reader.floats(g.get("radius"), 1, f"link {link!r} <{tag}> <{shape} radius>", (math.nan,))[0]
                if not radius > 0:
                    reader.fail(f"link {link!r} <{tag}> <{shape}>: needs radius > 0 m, got {g.get('radius')!r}")
                if shape == "cylinder" and abs(float((rot_l @ rot_g)[:, 2] @ axis)) < math.cos(_AXIS_TOLERANCE):
                    misaligned = True
                    continue
                radii.append(radius)
        if radii:
            return max(radii)
    if misaligned:
        reader.fail(
            f"wheel link {link!r}: its cylinder's axis (z of the geometry <origin>) is not along the wheel joint "
            "axis; fix the geometry origin's rpy or pass wheel_radius"
        )
    return None


def read_urdf(
    path_or_text: str | Path,
    *,
    gear_ratio: float,
    rotor_inertia: float | None = None,
    viscous_friction: Sequence[float] = (0.0, 0.0),
    coulomb_friction: Sequence[float] = (0.0, 0.0),
    wheel_radius: float | None = None,
    wheel_joints: Sequence[str] | None = None,
    rotor_joints: Sequence[str] | None = None,
    symmetry_tolerance: float = 0.02,
) -> UrdfModel:
    """The paper's physical parameters from a URDF, with the wheel and rotor joints found.

    path_or_text : a URDF file, or its XML text (a string starting with "<").
    gear_ratio : k_r (rotor speed / wheel speed), > 0; a URDF has no gear ratio.
    rotor_inertia : I_r (kg m^2), each rotor's inertia about its axle, when the URDF has no rotor links
        (default 0); refused when it has them (they give I_r).
    viscous_friction, coulomb_friction : (F_v1, F_v2) in N m s/rad and (F_d1, F_d2) in N m, (right, left).
    wheel_radius : r (m), overriding the wheel geometry (needed when the wheels are meshes).
    wheel_joints, rotor_joints : (right, left) joint names, overriding the search; ``rotor_joints=()``
        means "no rotor links".
    symmetry_tolerance : relative difference allowed between right and left values (averaged).

    See the module docstring for what is read where.  Raises RobotFileError (file) or UsageError
    (arguments).
    """
    k_r = _check_number("gear_ratio", gear_ratio, positive=True)
    f_v = _pair("viscous_friction", viscous_friction)
    f_d = _pair("coulomb_friction", coulomb_friction)
    if wheel_radius is not None:
        wheel_radius = _check_number("wheel_radius", wheel_radius, positive=True)
    if rotor_inertia is not None:
        rotor_inertia = _check_number("rotor_inertia", rotor_inertia)
    tol = _check_number("symmetry_tolerance", symmetry_tolerance)
    root, source = load(path_or_text)
    reader = Reader(root, source)

    # The links rigidly attached to the root: where wheels and rotors are mounted.
    body_links, stack = set(), [reader.root]
    while stack:
        name = stack.pop()
        body_links.add(name)
        stack.extend(j.child for j in reader.children[name] if j.kind == "fixed")

    # Rotors.
    moving = ("continuous", "revolute")
    if rotor_joints is not None:
        if len(rotor_joints) not in (0, 2):
            raise UsageError(f"rotor_joints must be (right, left) or () for none, got {rotor_joints!r}")
        rotors = [_named_joint(reader, n, "rotor", moving) for n in rotor_joints]
    else:
        rotors = [
            j
            for j in reader.joints.values()
            if j.kind != "fixed" and (_is_rotor_name(j.name) or _is_rotor_name(j.child))
        ]
        if len(rotors) not in (0, 2):
            names = ", ".join(repr(j.name) for j in rotors)
            reader.fail(
                f"found {len(rotors)} rotor joints ({names}); expected two (right, left) or none: "
                "name them with rotor_joints=(right, left), or rotor_joints=() for none"
            )
    rotor_names = {j.name for j in rotors}

    # Wheels.
    if wheel_joints is not None:
        if len(wheel_joints) != 2 or wheel_joints[0] == wheel_joints[1]:
            raise UsageError(f"wheel_joints must be two different joint names (right, left), got {wheel_joints!r}")
        wheels = [_named_joint(reader, n, "wheel", moving) for n in wheel_joints]
    else:
        wheels = [
            j
            for j in reader.joints.values()
            if j.kind == "continuous"
            and j.parent in body_links
            and j.name not in rotor_names
            and not _is_rotor_name(j.name)
            and not _is_rotor_name(j.child)
            and not _is_caster_name(j.name)
            and not _is_caster_name(j.child)
        ]
        if len(wheels) != 2:
            names = ", ".join(repr(j.name) for j in wheels) or "none"
            reader.fail(
                f"found {len(wheels)} drive-wheel joints ({names}); expected exactly two continuous joints from "
                f"{reader.root!r} (or a link fixed to it) to the wheels: name them with wheel_joints=(right, left)"
            )
    if rotor_names & {j.name for j in wheels}:
        raise UsageError("a joint cannot be both a wheel joint and a rotor joint")
    right, left = _sides(reader, wheels, "wheels", given=wheel_joints is not None)
    rotor_pair = _sides(reader, rotors, "rotors", given=rotor_joints is not None) if rotors else None

    # Axle.
    p_right, p_left = reader.pose[right.child][1], reader.pose[left.child][1]
    centre = 0.5 * (p_right + p_left)
    b = 0.5 * math.hypot(*(p_left - p_right)[:2])
    if abs(p_left[0] - p_right[0]) > tol * 2 * b:
        reader.fail(
            f"wheel joints {right.name!r} and {left.name!r} are at x = {p_right[0]:.4g} and {p_left[0]:.4g} m: the "
            "axle is not along y; the root frame must have x forward (ROS REP 103)"
        )
    signs = []
    for joint in (right, left):
        axis = reader.axis_in_root(joint)
        if abs(axis[1]) < math.cos(_AXIS_TOLERANCE):
            reader.fail(
                f"wheel joint {joint.name!r}: its axis is ({axis[0]:.3g}, {axis[1]:.3g}, {axis[2]:.3g}) in the root "
                "frame, not along y; fix <axis xyz> / the joint rpy, or name the wheels with wheel_joints"
            )
        signs.append(1 if axis[1] > 0 else -1)

    # Wheel bodies.
    wheel_values = []
    for joint in (right, left):
        link = joint.child
        body = reader.body(reader.subtree(link))
        if body is None:
            reader.fail(f"wheel link {link!r} (joint {joint.name!r}) has no <inertial> with mass > 0; export it")
        off_axis = _off_axis(reader, joint, body.com)
        radius = wheel_radius if wheel_radius is not None else _wheel_radius(reader, link, reader.axis_in_root(joint))
        if radius is None:
            reader.fail(
                f"wheel link {link!r} has no <collision> or <visual> cylinder or sphere (meshes are not read): "
                "pass wheel_radius (m)"
            )
        if off_axis > tol * radius:
            reader.fail(
                f"wheel link {link!r}: its centre of mass is {off_axis * 1000:.3g} mm off its axle (joint "
                f"{joint.name!r}); the paper's wheels are balanced: fix the <inertial> origin"
            )
        a_i = math.hypot(*(body.com - centre)[:2])
        wheel_values.append((body.mass, _spin_inertia(reader, joint, body), float(body.inertia[2, 2]), a_i, radius))
    (m_1, iw_1, iwm_1, a_1, r_1), (m_2, iw_2, iwm_2, a_2, r_2) = wheel_values
    m_w = _mean_checked(reader, f"wheel masses ({right.child!r}, {left.child!r})", m_1, m_2, tol)
    i_w = _mean_checked(reader, "wheel inertias about the axle", iw_1, iw_2, tol)
    i_wm = _mean_checked(reader, "wheel inertias about the vertical", iwm_1, iwm_2, tol)
    _mean_checked(reader, "wheel centre-of-mass distances from the axle midpoint (a)", a_1, a_2, tol, b)
    a = math.sqrt((m_1 * a_1**2 + m_2 * a_2**2) / (m_1 + m_2))  # keeps 2 m_w a^2 exact
    r = _mean_checked(reader, "wheel radii", r_1, r_2, tol)

    # Rotors.
    if rotor_pair is not None:
        if rotor_inertia is not None:
            raise UsageError(
                f"{source}: has rotor links ({rotor_pair[0].name!r}, {rotor_pair[1].name!r}), which give I_r; "
                f"drop {option('rotor_inertia')} (or, in Python, pass rotor_joints=() to ignore them)"
            )
        rotor_values = []
        for joint in rotor_pair:
            body = reader.body(reader.subtree(joint.child))
            if body is None:
                reader.fail(f"rotor link {joint.child!r} (joint {joint.name!r}) has no <inertial> with mass > 0")
            rel = body.com - centre
            rotor_values.append((body.mass, _spin_inertia(reader, joint, body), float(body.inertia[2, 2]), *rel[:2]))
        (mr_1, ir_1, irm_1, x_1, y_1), (mr_2, ir_2, irm_2, x_2, y_2) = rotor_values
        m_r = _mean_checked(reader, "rotor masses", mr_1, mr_2, tol)
        i_r = _mean_checked(reader, "rotor inertias about their axles", ir_1, ir_2, tol)
        i_rm = _mean_checked(reader, "rotor inertias about the vertical", irm_1, irm_2, tol)
        c_x = _mean_checked(reader, "rotor x (c_x)", x_1, x_2, tol, b)
        c_y = _mean_checked(reader, "rotor |y| (c_y)", -y_1, y_2, tol, b)
        rotor_links = {n for j in rotor_pair for n in reader.subtree(j.child)}
    else:
        m_r = i_rm = c_x = c_y = 0.0
        i_r = rotor_inertia if rotor_inertia is not None else 0.0
        rotor_links = set()

    # Platform: everything else.
    wheel_links = {n for j in (right, left) for n in reader.subtree(j.child)}
    platform_links = [n for n in reader.links if n not in wheel_links | rotor_links]
    platform = reader.body(platform_links)
    if platform is None:
        reader.fail(
            f"no <inertial> with mass > 0 on {reader.root!r} or any link other than the wheels and rotors: "
            "the platform's mass is unknown; export the base link's inertial"
        )
    d = platform.com - centre
    try:
        params = PhysicalParameters(
            I_p=float(platform.inertia[2, 2]), m_p=platform.mass, d_x=float(d[0]), d_y=float(d[1]),
            I_wm=i_wm, I_w=i_w, m_w=m_w, a=a, m_r=m_r, I_rm=i_rm, I_r=i_r, c_x=c_x, c_y=c_y, k_r=k_r, r=r, b=b,
            F_v1=f_v[0], F_v2=f_v[1], F_d1=f_d[0], F_d2=f_d[1],
        )  # fmt: skip
    except RobotFileError as err:
        raise RobotFileError(f"{source}: {err}") from None
    return UrdfModel(
        name=reader.name,
        params=params,
        right_wheel_joint=right.name,
        left_wheel_joint=left.name,
        wheel_signs=(signs[0], signs[1]),
        rotor_joints=(rotor_pair[0].name, rotor_pair[1].name) if rotor_pair is not None else None,
        dynamics=_wheel_dynamics(reader, root, (right.name, left.name)),
    )


def _wheel_dynamics(
    reader: Reader, root: Any, joints: tuple[str, str]
) -> tuple[tuple[float, float], tuple[float, float]] | None:
    """The wheel joints' <dynamics damping friction> ((right, left) each), None when neither joint has one."""
    found = {el.get("name"): el.find("dynamics") for el in root.findall("joint") if el.get("name") in joints}
    if all(found.get(j) is None for j in joints):
        return None
    out = []
    for attr in ("damping", "friction"):
        pair = []
        for j in joints:
            el = found.get(j)
            text = el.get(attr) if el is not None else None
            value = float(reader.floats(text, 1, f"joint {j!r} <dynamics {attr}>", (0.0,))[0])
            pair.append(_check_number(f"joint {j!r} <dynamics {attr}>", value))
        out.append((pair[0], pair[1]))
    return out[0], out[1]


def robot_from_urdf(path_or_text: str | Path, **options: Any) -> PhysicalParameters:
    """The paper's physical parameters (SI) from a URDF; ``options`` are the keyword arguments of :func:`read_urdf`."""
    return read_urdf(path_or_text, **options).params


def load_robot_urdf(
    path: str | Path,
    *,
    gear_ratio: float,
    rotor_inertia: float | None = None,
    viscous_friction: Sequence[float] | None = None,
    coulomb_friction: Sequence[float] | None = None,
    wheel_radius: float | None = None,
    wheel_joints: Sequence[str] | None = None,
    rotor_joints: Sequence[str] | None = None,
    symmetry_tolerance: float = 0.02,
    nominal: PhysicalParameters | None = None,
    name: str | None = None,
    torque_constant: float | None = None,
    efficiency: float | None = None,
) -> Robot:
    """A :class:`~wmrid.model.robot.Robot` from a URDF file: ``cad`` is what the URDF gives (:func:`read_urdf`).

    viscous_friction, coulomb_friction : (right, left); not given: 0 in the parameters, and unknown as CAD values
        (``Robot.unknown_cad``: a comparison shows "—", not a difference from 0).
    nominal : the estimator's starting point; default the URDF's parameters themselves.
    name : default the URDF's <robot name>, else the file name without extension.
    torque_constant : k_t (N m/A) of each motor; efficiency : of the gearbox, in (0, 1].
    """
    register_input(path)
    model = read_urdf(
        path, gear_ratio=gear_ratio, rotor_inertia=rotor_inertia,
        viscous_friction=(0.0, 0.0) if viscous_friction is None else viscous_friction,
        coulomb_friction=(0.0, 0.0) if coulomb_friction is None else coulomb_friction,
        wheel_radius=wheel_radius, wheel_joints=wheel_joints, rotor_joints=rotor_joints,
        symmetry_tolerance=symmetry_tolerance,
    )  # fmt: skip
    if model.dynamics is not None and (viscous_friction is None or coulomb_friction is None):
        # the wheel joints' <dynamics> (an exported URDF's identified friction) where no argument gives it
        given_v = model.dynamics[0] if viscous_friction is None else tuple(viscous_friction)
        given_d = model.dynamics[1] if coulomb_friction is None else tuple(coulomb_friction)
        model = replace(model, params=model.params.replace(
            F_v1=given_v[0], F_v2=given_v[1], F_d1=given_d[0], F_d2=given_d[1]))  # fmt: skip
        viscous_friction, coulomb_friction = given_v, given_d
    unknown = (("Fv1", "Fv2") if viscous_friction is None else ()) + (
        ("Fd1", "Fd2") if coulomb_friction is None else ()
    )
    if torque_constant is not None:
        torque_constant = _check_number("torque_constant", torque_constant, positive=True)
    if efficiency is not None and not 0 < _check_number("efficiency", efficiency, positive=True) <= 1:
        raise UsageError(f"efficiency must be in (0, 1], got {efficiency!r}")
    return Robot(
        name=name or model.name or Path(path).stem,
        nominal=nominal if nominal is not None else model.params,
        cad=model.params,
        torque_constant=torque_constant,
        efficiency=efficiency,
        unknown_cad=unknown,
    )
