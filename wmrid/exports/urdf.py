"""The identified robot as a URDF: the user's own URDF with only the base link's ``<inertial>`` and the wheel joints'
``<dynamics>`` changed (every other byte kept), or a minimal URDF from a TOML robot.

Editing a URDF (:func:`updated_urdf`).  wmrid reads a URDF's platform as every link that is neither a wheel nor a rotor,
merged (:mod:`wmrid.model.urdf`).  The identified platform (m_p, d_x, d_y, I_p: :mod:`wmrid.model.physical`) is put
into one of them, the *base link* -- the platform link with the largest mass of its own -- so that the merged platform
has exactly the identified values; the other links (casters, sensors) keep theirs:

* mass: m_base = m_p - (the other platform links' mass);
* centre of mass: (x, y) such that the merged centre of mass is at O + (d_x, d_y) (O the axle midpoint); z kept (no
  wheel log determines the height);
* inertia: the tensor is scaled, in its own frame (rpy kept), until its yaw component in the root frame makes the
  merged platform's yaw inertia about its centre of mass I_p.  Scaling keeps the tensor physical (positive, the
  triangle inequalities); the roll and pitch inertias, which no wheel log determines, scale with it (a comment says
  so).

The wheel joints get ``<dynamics damping="F_v" friction="F_d"/>`` (N m s/rad, N m).  Both changed elements carry, as
an XML comment inside them, the std of each value and where it came from.  Offsets come from expat's byte indices,
so the rest of the file is copied byte for byte (tests diff the XML trees).

A TOML robot has no URDF to edit: :func:`minimal_urdf` writes base_link (the identified platform), two wheels on
continuous joints at y = -+b with a cylinder of radius r, and the rotors as links on continuous joints (their spin
inertia I_r; read back with the gear ratio), the casters as spheres on fixed joints with no mass.
"""

from __future__ import annotations

import math
import xml.parsers.expat
from dataclasses import dataclass

import numpy as np

from wmrid.core.errors import RobotFileError, UsageError
from wmrid.exports.xml_text import xml_attribute, xml_comment
from wmrid.model.robot import Caster, PhysicalParameters
from wmrid.model.urdf import read_urdf
from wmrid.model.urdf_tree import Reader, load


@dataclass(frozen=True)
class _Spans:
    """Byte spans [start, end) in the file: each link's <inertial>, each joint's <dynamics> (or where one goes: just
    before its end tag), and the indentation of the line each starts on."""

    inertial: dict[str, tuple[int, int]]
    dynamics: dict[str, tuple[int, int]]
    joint_end: dict[str, int]
    link: dict[str, tuple[int, int]]  # each link element, whole


def _spans(data: bytes, source: str) -> _Spans:
    parser = xml.parsers.expat.ParserCreate()
    stack: list[tuple[str, str | None, int]] = []  # (tag, name, start byte)
    inertial: dict[str, tuple[int, int]] = {}
    dynamics: dict[str, tuple[int, int]] = {}
    joint_end: dict[str, int] = {}
    link: dict[str, tuple[int, int]] = {}
    owner: list[str | None] = [None]

    def start(tag: str, attrs: dict[str, str]) -> None:
        stack.append((tag, attrs.get("name"), parser.CurrentByteIndex))
        if tag in ("link", "joint") and len(stack) == 2:
            owner[0] = attrs.get("name")

    def end(tag: str) -> None:
        _, _, begin = stack.pop()
        at = parser.CurrentByteIndex
        # the end of this element: after the '>' of its end tag (or of its own start tag when self-closing)
        stop = data.index(b">", at) + 1
        if tag == "inertial" and len(stack) == 2 and stack[1][0] == "link":
            inertial[str(stack[1][1])] = (begin, stop)
        elif tag == "dynamics" and len(stack) == 2 and stack[1][0] == "joint":
            dynamics[str(stack[1][1])] = (begin, stop)
        elif tag == "joint" and len(stack) == 1:
            joint_end[str(owner[0])] = at
        elif tag == "link" and len(stack) == 1:
            link[str(owner[0])] = (begin, stop)

    parser.StartElementHandler = start
    parser.EndElementHandler = end
    try:
        parser.Parse(data, True)
    except xml.parsers.expat.ExpatError as err:
        raise RobotFileError(f"{source}: not well-formed XML ({err})") from None
    return _Spans(inertial, dynamics, joint_end, link)


def _indent(data: bytes, at: int) -> str:
    line_start = data.rfind(b"\n", 0, at) + 1
    prefix = data[line_start:at]
    return prefix.decode("utf-8") if prefix.strip() == b"" else ""


def _fmt(value: float) -> str:
    return repr(float(value))


_comment = xml_comment


def updated_urdf(
    data: bytes,
    source: str,
    identified: PhysicalParameters,
    *,
    gear_ratio: float,
    rotor_inertia: float | None = None,
    wheel_radius: float | None = None,
    notes: dict[str, str] | None = None,
    provenance: str = "",
    said: list[str] | None = None,
) -> bytes:
    """The URDF ``data`` (bytes of ``source``) with the identified platform in its base link's <inertial> and the
    identified friction in its wheel joints' <dynamics> (module docstring).  ``notes``: quantity -> "value +/- std
    unit (source)" text for the comments; ``provenance``: one line.  Raises RobotFileError / UsageError (one line)
    when the URDF cannot hold the identified robot (the other platform links already weigh more than the identified
    platform, or hold more yaw inertia)."""
    notes = notes or {}
    found = read_urdf(data.decode("utf-8"), gear_ratio=gear_ratio, rotor_inertia=rotor_inertia,
                      wheel_radius=wheel_radius)  # fmt: skip
    reader = Reader(*load(data.decode("utf-8")))
    reader.source = source
    wheel_joints = (found.right_wheel_joint, found.left_wheel_joint)
    wheel_links = {n for j in wheel_joints for n in reader.subtree(reader.joints[j].child)}
    rotor_links = (
        {n for j in found.rotor_joints for n in reader.subtree(reader.joints[j].child)} if found.rotor_joints else set()
    )
    platform_links = [n for n in reader.links if n not in wheel_links | rotor_links]
    own = {n: reader.inertial(n) for n in platform_links}
    # the base link: the link the wheels hang from (the root-most platform link), whatever its own mass
    base = reader.joints[wheel_joints[0]].parent
    if base not in platform_links:
        raise UsageError(f"{source}: the wheels hang from {base!r}, which is not a platform link; cannot place the "
                         "identified platform")  # fmt: skip
    with_mass = [n for n in platform_links if n != base and own[n] is not None and own[n].mass > 0]
    others = reader.body(with_mass)
    m_o = others.mass if others is not None else 0.0
    p_right = reader.pose[reader.joints[wheel_joints[0]].child][1]
    p_left = reader.pose[reader.joints[wheel_joints[1]].child][1]
    centre = 0.5 * (p_right + p_left)
    old = own[base]
    m_b = identified.m_p - m_o
    if not m_b > 0:
        raise UsageError(
            f"{source}: the identified platform mass {identified.m_p:.4g} kg is not more than the URDF's other "
            f"platform links ({m_o:.4g} kg besides {base!r}); the URDF cannot hold this robot"
        )
    target = centre[:2] + np.array([identified.d_x, identified.d_y])
    com_o = others.com[:2] if others is not None else np.zeros(2)
    height = old.com[2] if old is not None and old.mass > 0 else (others.com[2] if others is not None else centre[2])
    com_b = np.array([*(identified.m_p * target - m_o * com_o) / m_b, height])
    spread = m_b * float(np.sum((com_b[:2] - target) ** 2))
    if others is not None:
        spread += float(others.inertia[2, 2]) + m_o * float(np.sum((com_o - target) ** 2))
    izz_new = identified.I_p - spread
    if not izz_new > 0:
        raise UsageError(
            f"{source}: the identified platform yaw inertia I_p = {identified.I_p:.4g} kg m^2 is less than the URDF's "
            f"other platform links and the offsets of their centres of mass hold ({spread:.4g} kg m^2 about the "
            "identified centre of mass); the URDF cannot hold this robot"
        )
    el = reader.links[base].find("inertial")
    rot_l, pos_l = reader.pose[base]
    origin = rot_l.T @ (com_b - pos_l)
    keys = ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")
    izz_old = float(old.inertia[2, 2]) if old is not None else 0.0
    origin_el = el.find("origin") if el is not None else None
    rpy_text = origin_el.get("rpy") if origin_el is not None and origin_el.get("rpy") is not None else "0 0 0"
    if izz_old > 0:
        scale = izz_new / izz_old
        inertia_el = el.find("inertia")
        local = {k: float(inertia_el.get(k)) * scale for k in keys}
        how = (f"the link's tensor is scaled, in its own frame, by {scale:.4g} (its roll and pitch inertias, which no "
               "wheel log determines, with it)")  # fmt: skip
        if said is not None and not 0.5 <= scale <= 2.0:
            said.append(f"{base!r}'s inertia tensor was scaled by {scale:.3g} to hold the identified yaw inertia")
    else:  # no tensor to scale: a flat plate's (Ixx + Iyy = Izz), in the root frame, carried into the link's
        rot = rot_l @ reader.origin(el, f"link {base!r} <inertial>")[0] if el is not None else rot_l
        flat = rot.T @ np.diag([0.5 * izz_new, 0.5 * izz_new, izz_new]) @ rot
        entries = (flat[0, 0], flat[0, 1], flat[0, 2], flat[1, 1], flat[1, 2], flat[2, 2])
        local = dict(zip(keys, entries, strict=True))
        how = "the link had no inertia tensor: a flat plate's is written (roll and pitch inertias are placeholders)"
        if said is not None:
            said.append(f"{base!r} had no inertia: a flat plate's tensor holding the identified yaw inertia was "
                        "written")  # fmt: skip
    if said is not None and (old is None or old.mass <= 0):
        said.append(f"the identified platform was put into {base!r}, which had no mass of its own")

    spans = _spans(data, source)
    comment = _comment(
        f"wmrid export: the identified platform (m_p, d_x, d_y, I_p) put into this link so that every platform link "
        f"together has it; {how}; the height of the centre of mass is kept. "
        + "; ".join(f"{k} = {v}" for k, v in notes.items() if k in ("m_p", "d_x", "d_y", "I_p", "m", "I"))
        + (f". {provenance}" if provenance else "")
    )

    def block(ind: str) -> str:
        inner = ind + "  "
        return (
            f"<inertial>\n{inner}{comment}\n"
            f'{inner}<origin xyz="{_fmt(origin[0])} {_fmt(origin[1])} {_fmt(origin[2])}" rpy="{rpy_text}"/>\n'
            f'{inner}<mass value="{_fmt(m_b)}"/>\n'
            f"{inner}<inertia " + " ".join(f'{k}="{_fmt(local[k])}"' for k in keys) + "/>\n"
            f"{ind}</inertial>"
        )

    if base in spans.inertial:
        begin, stop = spans.inertial[base]
        edit = (begin, stop, block(_indent(data, begin)))
    else:  # the link has no <inertial>: one is added (a self-closing <link/> opened up)
        begin, stop = spans.link[base]
        ind = _indent(data, begin)
        element = data[begin:stop].decode("utf-8")
        if element.rstrip().endswith("/>") and "</link>" not in element:
            opened = element.rstrip()[:-2].rstrip() + ">"
            edit = (begin, stop, f"{opened}\n{ind}  {block(ind + '  ')}\n{ind}</link>")
        else:
            close = data.rindex(b"</link>", begin, stop)
            line_start = data.rfind(b"\n", 0, close) + 1
            edit = (line_start, line_start, f"{ind}  {block(ind + '  ')}\n")
    edits = [edit]
    for joint, side, fv, fd in ((wheel_joints[0], "1", identified.F_v1, identified.F_d1),
                                (wheel_joints[1], "2", identified.F_v2, identified.F_d2)):  # fmt: skip
        text = _comment(
            f"wmrid export: identified friction; F_v{side} = {notes.get(f'F_v{side}', _fmt(fv))}, "
            f"F_d{side} = {notes.get(f'F_d{side}', _fmt(fd))}"
        )
        element = f'<dynamics damping="{_fmt(fv)}" friction="{_fmt(fd)}">{text}</dynamics>'
        if joint in spans.dynamics:
            a, z = spans.dynamics[joint]
            edits.append((a, z, element))
        else:
            at = spans.joint_end[joint]
            line_start = data.rfind(b"\n", 0, at) + 1
            ind = _indent(data, at)
            edits.append((line_start, line_start, f"{ind}  {element}\n"))
    out = bytearray()
    last = 0
    for a, z, text in sorted(edits):
        out += data[last:a] + text.encode("utf-8")
        last = z
    out += data[last:]
    return bytes(out)


def minimal_urdf(
    identified: PhysicalParameters,
    casters: tuple[Caster, ...],
    name: str,
    notes: dict[str, str],
    provenance: str,
    extra: list[str] | None = None,
) -> str:
    """A URDF of the identified robot built from its physical parameters (module docstring); read back by
    :func:`wmrid.model.urdf.read_urdf` with ``gear_ratio = k_r`` (and ``rotor_inertia = I_r`` when the rotors have no
    mass: then they are not links) to the same base parameters.  extra: sentences for the header comment."""
    p = identified
    flat = lambda yaw: (0.5 * yaw, 0.5 * yaw, yaw)  # noqa: E731 - a plate's tensor from its yaw inertia

    def inertial(mass: float, xyz: tuple[float, float, float], diag: tuple[float, float, float], ind: str) -> str:
        dx, dy, dz = (max(v, 1e-12) for v in diag)
        return (
            f'{ind}<inertial>\n{ind}  <origin xyz="{_fmt(xyz[0])} {_fmt(xyz[1])} {_fmt(xyz[2])}" rpy="0 0 0"/>\n'
            f'{ind}  <mass value="{_fmt(mass)}"/>\n'
            f'{ind}  <inertia ixx="{_fmt(dx)}" ixy="0" ixz="0" iyy="{_fmt(dy)}" iyz="0" izz="{_fmt(dz)}"/>\n'
            f"{ind}</inertial>\n"
        )

    lines = [
        '<?xml version="1.0" encoding="utf-8"?>\n',
        _comment(f"wmrid export: a minimal URDF of the identified robot {name}. {provenance}") + "\n",
        _comment("; ".join(f"{k} = {v}" for k, v in notes.items())) + "\n",
        _comment(
            "Placeholders no wheel log determines: the centre of mass at the axle's height, roll and pitch inertias "
            "of a flat plate (Ixx = Iyy = Izz / 2)." + "".join(f" {e[0].upper()}{e[1:]}." for e in extra or [])
        )
        + "\n",
        f'<robot name="{xml_attribute(name)}">\n',
        '  <link name="base_link">\n',
        inertial(p.m_p, (p.d_x, p.d_y, 0.0), flat(p.I_p), "    "),
        "  </link>\n",
    ]
    for side, sign, fv, fd in (("right", -1.0, p.F_v1, p.F_d1), ("left", 1.0, p.F_v2, p.F_d2)):
        # the wheel's centre of mass at distance a from O (its joint is at b, on the tread)
        lines += [
            f'  <link name="{side}_wheel">\n',
            inertial(p.m_w, (0.0, sign * (p.a - p.b), 0.0), (p.I_wm, p.I_w, p.I_wm), "    "),
            f'    <collision><origin xyz="0 0 0" rpy="{_fmt(math.pi / 2)} 0 0"/>'
            f'<geometry><cylinder radius="{_fmt(p.r)}" length="{_fmt(0.2 * p.r)}"/></geometry></collision>\n',
            "  </link>\n",
            f'  <joint name="{side}_wheel_joint" type="continuous">\n'
            f'    <origin xyz="0 {_fmt(sign * p.b)} 0" rpy="0 0 0"/>\n'
            f'    <parent link="base_link"/>\n    <child link="{side}_wheel"/>\n    <axis xyz="0 1 0"/>\n'
            f'    <dynamics damping="{_fmt(fv)}" friction="{_fmt(fd)}"/>\n'
            "  </joint>\n",
        ]
        if p.m_r > 0:  # a massless rotor is no URDF link: its I_r is given when reading back
            lines += [
                f'  <link name="{side}_rotor">\n',
                inertial(p.m_r, (0.0, 0.0, 0.0), (p.I_rm, p.I_r, p.I_rm), "    "),
                "  </link>\n",
                f'  <joint name="{side}_rotor_joint" type="continuous">\n'
                f'    <origin xyz="{_fmt(p.c_x)} {_fmt(sign * p.c_y)} 0" rpy="0 0 0"/>\n'
                f'    <parent link="base_link"/>\n    <child link="{side}_rotor"/>\n    <axis xyz="0 1 0"/>\n'
                "  </joint>\n",
            ]
    for i, c in enumerate(casters):
        lines += [
            f'  <link name="caster_{i}"><collision><geometry><sphere radius="{_fmt(c.radius)}"/></geometry>'
            "</collision></link>\n",
            f'  <joint name="caster_{i}_joint" type="fixed"><origin xyz="{_fmt(c.x)} {_fmt(c.y)} '
            f'{_fmt(c.radius - p.r)}" rpy="0 0 0"/><parent link="base_link"/><child link="caster_{i}"/></joint>\n',
        ]
    lines.append("</robot>\n")
    return "".join(lines)
