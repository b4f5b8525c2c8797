"""A URDF as a rigid-body tree: its links (mass, centre of mass, inertia, collision and visual shapes) and joints, each
placed in the root link's frame with every joint at position 0 (xacro refused, mesh-only links noted)."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import NoReturn

import numpy as np

from wmrid.core.errors import RobotFileError, cannot_read

_XACRO = "{http://www.ros.org/wiki/xacro}"


@dataclass(frozen=True)
class Joint:
    name: str
    kind: str
    parent: str
    child: str
    rotation: np.ndarray  # (3, 3) child frame in parent frame
    origin: np.ndarray  # (3,) m, child frame origin in parent frame
    axis: np.ndarray  # (3,) unit, in the child frame


@dataclass(frozen=True)
class Body:
    """A rigid body in the root frame: mass (kg), centre of mass (3,) m, inertia (3, 3) kg m^2 about it."""

    mass: float
    com: np.ndarray
    inertia: np.ndarray


def rpy_matrix(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """URDF's rotation (3, 3) for rpy in rad: Rz(yaw) Ry(pitch) Rx(roll) (fixed axes x, y, z)."""
    cr, sr, cp, sp, cy, sy = (
        math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch), math.cos(yaw), math.sin(yaw),
    )  # fmt: skip
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


class Reader:
    """One parsed URDF: links, joints, poses at zero joint position; errors name ``source``."""

    def __init__(self, root: ET.Element, source: str) -> None:
        self.source = source
        self.name = root.get("name")
        self.links: dict[str, ET.Element] = {}
        for el in root.findall("link"):
            name = self._name(el, "link")
            if name in self.links:
                self.fail(f"link {name!r} is defined twice; link names must be unique")
            self.links[name] = el
        if not self.links:
            self.fail("no <link> elements; is this a URDF (a <robot> with links and joints)?")
        self.joints: dict[str, Joint] = {}
        self.parent_joint: dict[str, Joint] = {}
        for el in root.findall("joint"):
            joint = self._joint(el)
            if joint.name in self.joints:
                self.fail(f"joint {joint.name!r} is defined twice; joint names must be unique")
            if joint.child in self.parent_joint:
                self.fail(f"link {joint.child!r} is the child of two joints; a URDF is a tree")
            self.joints[joint.name] = joint
            self.parent_joint[joint.child] = joint
        roots = [name for name in self.links if name not in self.parent_joint]
        if len(roots) != 1:
            what = ", ".join(roots) if roots else "none (a cycle)"
            self.fail(f"has {len(roots)} root links ({what}); a URDF is one tree with one root link")
        self.root = roots[0]
        self.children: dict[str, list[Joint]] = {name: [] for name in self.links}
        for joint in self.joints.values():
            self.children[joint.parent].append(joint)
        # Poses of every link in the root frame, joints at 0.
        self.pose: dict[str, tuple[np.ndarray, np.ndarray]] = {self.root: (np.eye(3), np.zeros(3))}
        stack = [self.root]
        while stack:
            parent = stack.pop()
            rot, pos = self.pose[parent]
            for joint in self.children[parent]:
                self.pose[joint.child] = (rot @ joint.rotation, rot @ joint.origin + pos)
                stack.append(joint.child)
        unreached = sorted(set(self.links) - set(self.pose))
        if unreached:
            self.fail(f"links {', '.join(unreached)} are not connected to the root link {self.root!r} (a cycle?)")

    def fail(self, message: str) -> NoReturn:
        raise RobotFileError(f"{self.source}: {message}")

    def _name(self, el: ET.Element, what: str) -> str:
        name = el.get("name")
        if not name:
            self.fail(f"a <{what}> has no name attribute")
        return str(name)

    def floats(self, text: str | None, n: int, where: str, default: Sequence[float]) -> np.ndarray:
        if text is None:
            return np.array(default, dtype=float)
        try:
            values = [float(v) for v in text.split()]
        except ValueError:
            values = []
        if len(values) != n or not all(math.isfinite(v) for v in values):
            self.fail(f"{where}: expected {n} finite number{'s' if n > 1 else ''}, got {text!r}")
        return np.array(values)

    def origin(self, el: ET.Element, where: str) -> tuple[np.ndarray, np.ndarray]:
        """(rotation, translation) of ``el``'s <origin> (identity when absent)."""
        origin = el.find("origin")
        if origin is None:
            return np.eye(3), np.zeros(3)
        xyz = self.floats(origin.get("xyz"), 3, f"{where} <origin xyz>", (0.0, 0.0, 0.0))
        rpy = self.floats(origin.get("rpy"), 3, f"{where} <origin rpy>", (0.0, 0.0, 0.0))
        return rpy_matrix(*rpy), xyz

    def _joint(self, el: ET.Element) -> Joint:
        name = self._name(el, "joint")
        where = f"joint {name!r}"
        kind = el.get("type", "")
        links = []
        for tag in ("parent", "child"):
            sub = el.find(tag)
            link = sub.get("link") if sub is not None else None
            if not link:
                self.fail(f"{where} has no <{tag} link=...>")
            if link not in self.links:
                self.fail(f"{where}: {tag} link {link!r} is not defined by any <link>")
            links.append(str(link))
        rotation, origin = self.origin(el, where)
        axis_el = el.find("axis")
        axis = self.floats(axis_el.get("xyz") if axis_el is not None else None, 3, f"{where} <axis>", (1, 0, 0))
        norm = float(np.linalg.norm(axis))
        if norm == 0.0 and kind not in ("fixed", "floating", "planar"):
            self.fail(f"{where}: <axis xyz> is the zero vector; give the rotation axis")
        return Joint(name, kind, links[0], links[1], rotation, origin, axis / norm if norm else axis)

    def inertial(self, link: str) -> Body | None:
        """The link's own <inertial> in the root frame, or None when it has none."""
        el = self.links[link].find("inertial")
        if el is None:
            return None
        where = f"link {link!r} <inertial>"
        mass_el = el.find("mass")
        mass = self.floats(mass_el.get("value") if mass_el is not None else None, 1, f"{where} <mass>", (math.nan,))
        if not math.isfinite(mass[0]) or mass[0] < 0:
            self.fail(f"{where}: needs <mass value=...> >= 0 kg, got {mass[0]}")
        inertia_el = el.find("inertia")
        if inertia_el is None:
            self.fail(f"{where}: no <inertia ixx=... ixy=... ixz=... iyy=... iyz=... izz=...> (kg m^2)")
        keys = ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")
        missing = [k for k in keys if inertia_el.get(k) is None]
        if missing:
            self.fail(f"{where} <inertia>: missing {', '.join(missing)} (kg m^2); a URDF gives all six")
        ixx, ixy, ixz, iyy, iyz, izz = (self.floats(inertia_el.get(k), 1, f"{where} {k}", ())[0] for k in keys)
        local = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
        rot_o, pos_o = self.origin(el, where)
        rot_l, pos_l = self.pose[link]
        rot = rot_l @ rot_o
        return Body(float(mass[0]), rot_l @ pos_o + pos_l, rot @ local @ rot.T)

    def subtree(self, link: str) -> list[str]:
        out, stack = [], [link]
        while stack:
            name = stack.pop()
            out.append(name)
            stack.extend(j.child for j in self.children[name])
        return out

    def body(self, links: Sequence[str]) -> Body | None:
        """The links' inertials merged (parallel-axis theorem); None when they have no mass."""
        parts = [b for b in (self.inertial(name) for name in links) if b is not None and b.mass > 0]
        if not parts:
            return None
        mass = sum(b.mass for b in parts)
        com = sum(b.mass * b.com for b in parts) / mass
        inertia = np.zeros((3, 3))
        for b in parts:
            d = b.com - com
            inertia += b.inertia + b.mass * (float(d @ d) * np.eye(3) - np.outer(d, d))
        return Body(mass, com, inertia)

    def axis_in_root(self, joint: Joint) -> np.ndarray:
        return self.pose[joint.child][0] @ joint.axis


def load(path_or_text: str | Path) -> tuple[ET.Element, str]:
    if isinstance(path_or_text, str) and path_or_text.lstrip().startswith("<"):
        data: bytes = path_or_text.encode("utf-8")
        source = "<URDF text>"
    else:
        path = Path(path_or_text)
        source = str(path)
        if not path.is_file():
            raise RobotFileError(f"{source}: no such URDF file")
        try:
            data = path.read_bytes()
        except OSError as err:
            raise RobotFileError(f"{source}: {cannot_read(err)}") from None
    try:
        root = ET.fromstring(data)
    except ET.ParseError as err:
        raise RobotFileError(f"{source}: not XML ({err}); a URDF is an XML file with a <robot> root") from None
    if any(isinstance(el.tag, str) and el.tag.startswith(_XACRO) for el in root.iter()):
        raise RobotFileError(f"{source}: contains xacro macros; expand it first: xacro {source} > robot.urdf")
    if root.tag != "robot":
        raise RobotFileError(f"{source}: the XML root is <{root.tag}>, not <robot>; is this a URDF?")
    return root, source
