"""Parse a URDF into a `RobotDescription`: links, joints, visuals and materials, no meshes.

yourdfpy's element parsers read each ``<link>``, ``<joint>`` and ``<material>``; this module
checks what they do not (joint types, the tree, mimic references) and wraps every failure
in a `UrdfError` naming the element, so a typo in a 10,000-link file is found by name.
yourdfpy never loads a mesh here: mesh files are resolved and read by `bridge.robots.model`.

Everything is linear in the size of the file (maps by name, one walk of the tree).
Lengths stay in METRES (the URDF's unit); conversion to mm happens in `model`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from types import MappingProxyType
from typing import Any, Mapping, Optional

import numpy as np
import numpy.typing as npt
from lxml import etree
from yourdfpy import URDF as _YourdfpyURDF

from bridge.robots.errors import UrdfError

__all__ = [
    "JOINT_TYPES",
    "MOVING_JOINT_TYPES",
    "Geometry",
    "VisualSpec",
    "LinkSpec",
    "JointLimits",
    "Mimic",
    "JointSpec",
    "RobotDescription",
    "parse_urdf",
]

F64 = npt.NDArray[np.float64]
Rgba = tuple[float, float, float, float]

JOINT_TYPES = ("revolute", "continuous", "prismatic", "fixed", "floating", "planar")
# Joint types forward kinematics moves; floating and planar are shown fixed (with a warning).
MOVING_JOINT_TYPES = ("revolute", "continuous", "prismatic")


@dataclass(frozen=True)
class Geometry:
    """One URDF ``<geometry>``: ``kind`` is mesh, box, cylinder or sphere (metres)."""

    kind: str
    filename: Optional[str] = None  # mesh URI as written in the URDF
    scale: tuple[float, float, float] = (1.0, 1.0, 1.0)
    size: tuple[float, float, float] = (0.0, 0.0, 0.0)  # box
    radius: float = 0.0  # cylinder, sphere
    length: float = 0.0  # cylinder


@dataclass(frozen=True)
class VisualSpec:
    """One ``<visual>`` of a link, its colour resolved from the URDF materials (or None)."""

    link: str
    index: int  # position among the link's visuals
    name: Optional[str]
    origin: F64  # 4x4, metres, visual frame in the link frame
    geometry: Geometry
    rgba: Optional[Rgba]  # from the URDF; None: ask the mesh file, else default grey
    material: Optional[str]  # the material's name, if any


@dataclass(frozen=True)
class LinkSpec:
    """``collisions``: the link's ``<collision>`` elements as the same spec (no colour); one
    whose geometry cannot be read is left out with a line in
    `RobotDescription.collision_warnings` (the robot still loads: Slicer shows visuals)."""

    name: str
    visuals: tuple[VisualSpec, ...] = ()
    collisions: tuple[VisualSpec, ...] = ()


@dataclass(frozen=True)
class JointLimits:
    lower: float
    upper: float
    effort: Optional[float] = None
    velocity: Optional[float] = None


@dataclass(frozen=True)
class Mimic:
    """This joint's position is ``multiplier * position(joint) + offset``."""

    joint: str
    multiplier: float = 1.0
    offset: float = 0.0


@dataclass(frozen=True)
class JointSpec:
    name: str
    type: str  # one of JOINT_TYPES
    parent: str
    child: str
    origin: F64  # 4x4, metres: child frame at zero position, in the parent link frame
    axis: F64  # (3,) unit vector in the joint frame
    limits: Optional[JointLimits] = None
    mimic: Optional[Mimic] = None

    @property
    def moves(self) -> bool:
        return self.type in MOVING_JOINT_TYPES


@dataclass(frozen=True)
class RobotDescription:
    """A parsed URDF. ``links`` and ``joints`` keep the file's order; ``child_joints`` maps
    a link to the joints whose parent it is; ``parent_joint`` maps a link to its joint."""

    name: str
    xml: str
    links: Mapping[str, LinkSpec]
    joints: Mapping[str, JointSpec]
    materials: Mapping[str, Rgba]
    root_link: str
    parent_joint: Mapping[str, str]
    child_joints: Mapping[str, tuple[str, ...]]
    warnings: tuple[str, ...] = field(default=())
    # <collision> elements that could not be read (only motion planning uses them).
    collision_warnings: tuple[str, ...] = field(default=())

    @property
    def moving_joints(self) -> tuple[str, ...]:
        """Joints that move (revolute, continuous, prismatic), mimic joints included."""
        return tuple(n for n, j in self.joints.items() if j.moves)

    @property
    def actuated_joints(self) -> tuple[str, ...]:
        """Moving joints that are not mimic joints: the ones a joint state should give."""
        return tuple(n for n, j in self.joints.items() if j.moves and j.mimic is None)


# ---------------------------------------------------------------------------- helpers


def _where(element: Any) -> str:
    line = getattr(element, "sourceline", None)
    return f" (line {line})" if line else ""


def _element_name(element: Any, tag: str) -> str:
    name = element.get("name")
    if name is None or not name.strip():
        raise UrdfError(f"<{tag}>{_where(element)}", "a non-empty 'name' attribute",
                        "none")
    return str(name)


def _explain(exc: BaseException) -> str:
    if isinstance(exc, KeyError):
        return f"missing attribute {exc.args[0]!r}" if exc.args else "a missing attribute"
    if isinstance(exc, (AttributeError, TypeError, IndexError)):
        return f"a missing or empty sub-element ({exc})"
    return f"{type(exc).__name__}: {exc}"


def _floats(value: Any, count: int, what: str) -> tuple[float, ...]:
    # Plain Python on purpose: called for every origin and axis of a 10,000-link file.
    items = value.tolist() if isinstance(value, np.ndarray) else value
    if np.ndim(items) == 0:
        items = [items]
    try:
        out = tuple(float(x) for x in items)
    except (TypeError, ValueError):
        raise UrdfError(what, f"{count} finite numbers", value) from None
    if len(out) != count or not all(math.isfinite(x) for x in out):
        raise UrdfError(what, f"{count} finite numbers", list(out))
    return out


def _rgba(color: Any, what: str) -> Optional[Rgba]:
    if color is None or getattr(color, "rgba", None) is None:
        return None
    values = _floats(color.rgba, 4, what)
    if any(v < 0.0 or v > 1.0 for v in values):
        raise UrdfError(what, "4 numbers in 0..1 (rgba)", list(values))
    return values[0], values[1], values[2], values[3]


def _origin(matrix: Any, what: str) -> F64:
    if matrix is None:
        return np.eye(4)
    m = np.asarray(matrix, dtype=np.float64)
    if m.shape != (4, 4) or not np.all(np.isfinite(m)):
        raise UrdfError(what, "xyz and rpy of 3 finite numbers each", m.tolist())
    return m


def _check_origin_text(element: Any, what: str) -> None:
    """yourdfpy accepts 'xyz="1 2"' silently in places; refuse wrong counts by name."""
    origin = element.find("origin")
    if origin is None:
        return
    for attr in ("xyz", "rpy"):
        text = origin.get(attr)
        if text is None:
            continue
        try:
            _floats([float(t) for t in text.split()], 3, f"{what} <origin> {attr}")
        except ValueError:
            raise UrdfError(f"{what} <origin> {attr}", "3 numbers", text) from None


# ---------------------------------------------------------------------------- parsing


def _geometry(raw: Any, what: str) -> Geometry:
    if raw is None:
        raise UrdfError(what, "a <geometry> element", "none")
    if raw.mesh is not None:
        filename = raw.mesh.filename
        if not filename:
            raise UrdfError(f"{what} <mesh>", "a 'filename' attribute", "none")
        scale = raw.mesh.scale
        if scale is None:
            s3 = (1.0, 1.0, 1.0)
        elif np.ndim(scale) == 0:
            s = float(scale)
            s3 = (s, s, s)
        else:
            s3 = _floats(scale, 3, f"{what} <mesh> scale")  # type: ignore[assignment]
        return Geometry("mesh", filename=str(filename), scale=s3)
    if raw.box is not None:
        size = _floats(raw.box.size, 3, f"{what} <box> size")
        return Geometry("box", size=size)  # type: ignore[arg-type]
    if raw.cylinder is not None:
        return Geometry("cylinder", radius=float(raw.cylinder.radius),
                        length=float(raw.cylinder.length))
    if raw.sphere is not None:
        return Geometry("sphere", radius=float(raw.sphere.radius))
    raise UrdfError(what, "one of <mesh>, <box>, <cylinder>, <sphere>", "none")


def _visuals(raw_link: Any, named: Mapping[str, Rgba],
             inline_named: dict[str, Rgba], warnings: list[str]) -> tuple[VisualSpec, ...]:
    out = []
    link = raw_link.name
    for index, raw in enumerate(raw_link.visuals):
        what = f"link {link!r} visual {index}"
        geometry = _geometry(raw.geometry, what)
        rgba: Optional[Rgba] = None
        material_name: Optional[str] = None
        mat = raw.material
        if mat is not None:
            material_name = mat.name
            rgba = _rgba(mat.color, f"{what} <material> <color> rgba")
            if rgba is None and material_name:
                rgba = named.get(material_name) or inline_named.get(material_name)
                if rgba is None:
                    warnings.append(f"{what}: material {material_name!r} has no colour "
                                    f"defined anywhere in the URDF; using the mesh's colour "
                                    f"or the default grey")
            elif rgba is not None and material_name and material_name not in inline_named:
                # urdfdom lets a later visual refer to a colour first given inline.
                inline_named[material_name] = rgba
            if mat.texture is not None and rgba is None:
                warnings.append(f"{what}: material textures are not supported; using the "
                                f"mesh's colour or the default grey")
        out.append(VisualSpec(link, index, raw.name, _origin(raw.origin, f"{what} <origin>"),
                              geometry, rgba, material_name))
    return tuple(out)


def _collisions(raw_link: Any, warnings: list[str]) -> tuple[VisualSpec, ...]:
    out = []
    for index, raw in enumerate(raw_link.collisions):
        what = f"link {raw_link.name!r} collision {index}"
        try:
            spec = VisualSpec(raw_link.name, index, raw.name,
                              _origin(raw.origin, f"{what} <origin>"),
                              _geometry(raw.geometry, what), None, None)
        except UrdfError as error:
            warnings.append(f"{what} left out: {error}")
            continue
        out.append(spec)
    return tuple(out)


def _joint(raw: Any, warnings: list[str]) -> JointSpec:
    what = f"joint {raw.name!r}"
    if raw.type not in JOINT_TYPES:
        raise UrdfError(f"{what} type", "one of " + ", ".join(JOINT_TYPES), raw.type)
    if not raw.parent or not raw.child:
        raise UrdfError(what, "<parent link=...> and <child link=...>",
                        f"parent {raw.parent!r}, child {raw.child!r}")
    axis = np.asarray(_floats(raw.axis, 3, f"{what} <axis> xyz"), dtype=np.float64)
    norm = float(np.linalg.norm(axis))
    if raw.type in MOVING_JOINT_TYPES and norm < 1e-12:
        raise UrdfError(f"{what} <axis> xyz", "a non-zero vector", axis.tolist())
    axis = axis / norm if norm > 0 else np.array([1.0, 0.0, 0.0])
    limits: Optional[JointLimits] = None
    if raw.limit is not None:
        lower = 0.0 if raw.limit.lower is None else float(raw.limit.lower)
        upper = 0.0 if raw.limit.upper is None else float(raw.limit.upper)
        if not (math.isfinite(lower) and math.isfinite(upper)):
            raise UrdfError(f"{what} <limit>", "finite lower and upper", (lower, upper))
        limits = JointLimits(lower, upper, raw.limit.effort, raw.limit.velocity)
    elif raw.type in ("revolute", "prismatic"):
        # urdfdom (and so robot_state_publisher) refuses this too.
        raise UrdfError(f"{what} <limit>", f"a <limit> element (a {raw.type} joint needs one)",
                        "none")
    mimic: Optional[Mimic] = None
    if raw.mimic is not None:
        if not raw.mimic.joint:
            raise UrdfError(f"{what} <mimic>", "a 'joint' attribute", "none")
        mult = 1.0 if raw.mimic.multiplier is None else float(raw.mimic.multiplier)
        off = 0.0 if raw.mimic.offset is None else float(raw.mimic.offset)
        mimic = Mimic(str(raw.mimic.joint), mult, off)
    if raw.type in ("floating", "planar"):
        warnings.append(f"{what}: {raw.type} joints are shown fixed at their origin")
    return JointSpec(raw.name, raw.type, raw.parent, raw.child,
                     _origin(raw.origin, f"{what} <origin>"), axis, limits, mimic)


def _parse_xml(xml: str | bytes) -> Any:
    data = xml.encode("utf-8") if isinstance(xml, str) else xml
    # No entity expansion, no network: a URDF may come from any ROS node.
    parser = etree.XMLParser(resolve_entities=False, no_network=True, remove_comments=True,
                             huge_tree=True)
    try:
        root = etree.fromstring(data, parser=parser)
    except etree.XMLSyntaxError as exc:
        raise UrdfError("URDF", "well-formed XML", str(exc)) from None
    except ValueError as exc:  # e.g. an encoding declaration in a str
        raise UrdfError("URDF", "well-formed XML", str(exc)) from None
    if root is None:
        raise UrdfError("URDF", "an XML document", "nothing")
    tag = etree.QName(root).localname if isinstance(root.tag, str) else str(root.tag)
    if tag != "robot":
        raise UrdfError("URDF root element", "<robot>", f"<{tag}>")
    return root


def parse_urdf(xml: str | bytes) -> RobotDescription:
    """Parse URDF text into a `RobotDescription`; raises `UrdfError` naming what is wrong."""
    root = _parse_xml(xml)
    robot_name = _element_name(root, "robot")
    warnings: list[str] = []

    named: dict[str, Rgba] = {}
    for el in root.iterfind("material"):
        name = _element_name(el, "material")
        try:
            raw = _YourdfpyURDF._parse_material(el)
        except Exception as exc:
            raise UrdfError(f"material {name!r}{_where(el)}", "a valid <material>",
                            _explain(exc)) from None
        rgba = _rgba(raw.color, f"material {name!r} <color> rgba")
        if rgba is not None:
            named[name] = rgba

    links: dict[str, LinkSpec] = {}
    inline_named: dict[str, Rgba] = {}
    collision_warnings: list[str] = []
    for el in root.iterfind("link"):
        name = _element_name(el, "link")
        if name in links:
            raise UrdfError(f"link {name!r}{_where(el)}", "a unique link name", "a duplicate")
        for index, visual_el in enumerate(el.findall("visual")):
            _check_origin_text(visual_el, f"link {name!r} visual {index}")
        try:
            raw = _YourdfpyURDF._parse_link(el)
        except Exception as exc:
            raise UrdfError(f"link {name!r}{_where(el)}", "a valid <link>",
                            _explain(exc)) from None
        links[name] = LinkSpec(name, _visuals(raw, named, inline_named, warnings),
                               _collisions(raw, collision_warnings))
    if not links:
        raise UrdfError(f"robot {robot_name!r}", "at least one <link>", "none")

    joints: dict[str, JointSpec] = {}
    parent_joint: dict[str, str] = {}
    children: dict[str, list[str]] = {}
    for el in root.iterfind("joint"):
        name = _element_name(el, "joint")
        if name in joints:
            raise UrdfError(f"joint {name!r}{_where(el)}", "a unique joint name", "a duplicate")
        _check_origin_text(el, f"joint {name!r}")
        try:
            raw = _YourdfpyURDF._parse_joint(el)
        except Exception as exc:
            raise UrdfError(f"joint {name!r}{_where(el)}", "a valid <joint>",
                            _explain(exc)) from None
        joint = _joint(raw, warnings)
        for role, link in (("parent", joint.parent), ("child", joint.child)):
            if link not in links:
                raise UrdfError(f"joint {name!r} <{role}>", "the name of a <link>", link)
        if joint.child in parent_joint:
            raise UrdfError(f"link {joint.child!r}", "one parent joint",
                            f"joints {parent_joint[joint.child]!r} and {name!r}")
        joints[name] = joint
        parent_joint[joint.child] = name
        children.setdefault(joint.parent, []).append(name)

    for joint in list(joints.values()):
        if joint.mimic is not None:
            source = joints.get(joint.mimic.joint)
            if source is None:
                # robot_state_publisher skips such a mimic and shows the rest: so do we.
                warnings.append(f"joint {joint.name!r} mimics {joint.mimic.joint!r}, which is "
                                f"not a joint of this robot: the mimic is ignored and "
                                f"{joint.name!r} moves by its own joint state")
                joints[joint.name] = replace(joint, mimic=None)
                continue
            if not source.moves:
                warnings.append(f"joint {joint.name!r} mimics {source.name!r}, a "
                                f"{source.type} joint: its position is always the offset")
    _check_mimic_cycles(joints)

    roots = [name for name in links if name not in parent_joint]
    if len(roots) != 1:
        raise UrdfError(f"robot {robot_name!r}", "exactly one root link (a link no joint "
                        "has as child)", f"{len(roots)}: {roots[:5]}")
    # Walk the tree once: every link must hang from the root (no cycles, no islands).
    seen = 1
    stack = [roots[0]]
    while stack:
        for joint_name in children.get(stack.pop(), ()):
            seen += 1
            stack.append(joints[joint_name].child)
    if seen != len(links):
        stranded = [n for n in links if n not in _reachable(roots[0], children, joints)]
        raise UrdfError(f"robot {robot_name!r}", "a tree of links from the root "
                        f"{roots[0]!r}", f"links in a loop: {stranded[:5]}")

    text = xml.decode("utf-8", errors="replace") if isinstance(xml, bytes) else xml
    return RobotDescription(
        name=robot_name, xml=text, links=MappingProxyType(links),
        joints=MappingProxyType(joints), materials=MappingProxyType(named),
        root_link=roots[0], parent_joint=MappingProxyType(parent_joint),
        child_joints=MappingProxyType({k: tuple(v) for k, v in children.items()}),
        warnings=tuple(warnings), collision_warnings=tuple(collision_warnings))


def _reachable(root: str, children: Mapping[str, list[str]],
               joints: Mapping[str, JointSpec]) -> set[str]:
    seen = {root}
    stack = [root]
    while stack:
        for joint_name in children.get(stack.pop(), ()):
            child = joints[joint_name].child
            if child not in seen:
                seen.add(child)
                stack.append(child)
    return seen


def _check_mimic_cycles(joints: Mapping[str, JointSpec]) -> None:
    state: dict[str, int] = {}  # 1 = on the current path, 2 = done
    for start in joints:
        path = []
        name: Optional[str] = start
        while name is not None and state.get(name) is None:
            state[name] = 1
            path.append(name)
            mimic = joints[name].mimic
            name = mimic.joint if mimic is not None else None
        if name is not None and state.get(name) == 1:
            raise UrdfError(f"joint {name!r} <mimic>", "mimic references without a loop",
                            " -> ".join(path + [name]))
        for visited in path:
            state[visited] = 2
