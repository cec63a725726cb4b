"""ROS 2 interface package folders: finding them, reading their package.xml, ordering them.

Standard library only: tools/setup_env.py runs this with whatever Python it was given.
"""

from __future__ import annotations

import os
import re
import xml.etree.ElementTree as ElementTree
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterable, Sequence

from bridge.interfaces.errors import (DependencyCycleError, MissingDependencyError,
                                      NotAnInterfacePackage, PackageError)

# The package.xml tags whose packages must exist when this one is built or used.
DEPENDENCY_TAGS = ("depend", "build_depend", "exec_depend")
# What REP 149 conditions (`condition="$ROS_VERSION == 2"`) are evaluated against here.
CONDITION_CONTEXT = {"ROS_VERSION": "2", "ROS_DISTRO": "jazzy", "ROS_PYTHON_VERSION": "3"}
# Folders colcon would not look into either.
IGNORE_MARKERS = ("COLCON_IGNORE", "AMENT_IGNORE", "CATKIN_IGNORE")
_GENERATES_INTERFACES = re.compile(r"\brosidl_generate_interfaces\s*\(")
_KINDS = ("msg", "srv", "action")


@dataclass(frozen=True)
class InterfacePackage:
    name: str
    path: Path
    depends: tuple[str, ...]  # conditions evaluated, in package.xml order, no repeats

    def kinds(self) -> tuple[str, ...]:
        """The Python modules the build makes (`msg`, `srv`, `action`), from its folders."""
        return tuple(kind for kind in _KINDS
                     if any((self.path / kind).glob(f"*.{kind}")))


def read_package(folder: Path) -> InterfacePackage:
    """Read `folder/package.xml`; `PackageError` if it is not an interface package."""
    manifest = folder / "package.xml"
    try:
        root = ElementTree.parse(manifest).getroot()
    except (OSError, ElementTree.ParseError) as error:
        raise PackageError(f"{manifest}: expected a readable package.xml, got {error}") from None
    name = (root.findtext("name") or "").strip()
    if root.tag != "package" or not re.fullmatch(r"[a-z][a-z0-9_]*", name):
        raise PackageError(f"{manifest}: expected <package> with a <name> of lowercase letters, "
                           f"digits and _, got <{root.tag}> named {name!r}")
    cmake = folder / "CMakeLists.txt"
    try:
        generates = bool(_GENERATES_INTERFACES.search(cmake.read_text(errors="replace")))
    except OSError:
        generates = False
    if not generates:
        raise NotAnInterfacePackage(f"{folder}: expected an interface package (a "
                                    f"CMakeLists.txt that calls rosidl_generate_interfaces), "
                                    f"got none in {cmake}")
    depends: list[str] = []
    for element in root:
        if element.tag not in DEPENDENCY_TAGS:
            continue
        condition = element.get("condition")
        if condition and not evaluate_condition(condition, where=str(manifest)):
            continue
        dependency = (element.text or "").strip()
        if dependency and dependency != name and dependency not in depends:
            depends.append(dependency)
    return InterfacePackage(name, folder.resolve(), tuple(depends))


def find_packages(paths: Sequence[Path],
                  note: Callable[[str], None] = lambda _: None) -> list[InterfacePackage]:
    """The interface packages at or under `paths`: a package folder is taken as given (it must
    be an interface package); any other folder is searched as colcon would (no hidden or
    ignored folders, nothing below a package), and packages that generate no interfaces are
    skipped with a `note`. Raises `PackageError` for a bad path or two packages of a name."""
    found: dict[str, InterfacePackage] = {}

    def add(package: InterfacePackage) -> None:
        other = found.get(package.name)
        if other is not None and other.path != package.path:
            raise PackageError(f"expected one folder per package name, got two named "
                               f"{package.name}: {other.path} and {package.path}")
        found[package.name] = package

    for path in paths:
        if not path.is_dir():
            raise PackageError(f"expected a package folder or a folder of packages, got "
                               f"{path} ({'not a folder' if path.exists() else 'absent'})")
        if (path / "package.xml").is_file():
            add(read_package(path))
            continue
        before = len(found)
        for folder in _package_folders(path):
            try:
                add(read_package(folder))
            except NotAnInterfacePackage:
                note(f"skipping {folder}: not an interface package (no "
                     f"rosidl_generate_interfaces in its CMakeLists.txt)")
        if len(found) == before:
            raise PackageError(f"expected interface packages (folders with a package.xml) "
                               f"under {path}, found none")
    return list(found.values())


def _package_folders(top: Path) -> Iterable[Path]:
    for folder, subfolders, files in os.walk(top):
        here = Path(folder)
        if any(marker in files for marker in IGNORE_MARKERS):
            subfolders.clear()
            continue
        if "package.xml" in files:
            subfolders.clear()  # nothing below a package is another package
            yield here
            continue
        subfolders[:] = sorted(s for s in subfolders if not s.startswith("."))


def order_packages(packages: Sequence[InterfacePackage],
                   available: Callable[[str], bool]) -> list[InterfacePackage]:
    """`packages` with every package after those it depends on (ties keep the given order).

    A dependency outside `packages` must be `available` in the environment, else
    `MissingDependencyError` listing every such (package, dependency); a cycle among them is
    a `DependencyCycleError` naming it. Nothing is built before this has passed.
    """
    given = {p.name: p for p in packages}
    missing = [(p.name, d) for p in packages for d in p.depends
               if d not in given and not available(d)]
    if missing:
        raise MissingDependencyError(missing)
    ordered: list[InterfacePackage] = []
    placed: set[str] = set()
    remaining = list(packages)
    while remaining:
        ready = [p for p in remaining
                 if all(d in placed for d in p.depends if d in given)]
        if not ready:
            raise DependencyCycleError(_a_cycle(remaining, given))
        for package in ready:
            ordered.append(package)
            placed.add(package.name)
        remaining = [p for p in remaining if p.name not in placed]
    return ordered


def _a_cycle(stuck: Sequence[InterfacePackage],
             given: dict[str, InterfacePackage]) -> list[str]:
    """Follow in-set dependencies from a package that cannot be placed until one repeats."""
    names = {p.name for p in stuck}
    path = [stuck[0].name]
    while True:
        package = given[path[-1]]
        following = next(d for d in package.depends if d in names)
        if following in path:
            return path[path.index(following):] + [following]
        path.append(following)


# REP 149 conditions: `$VAR == value`, `!=`, `<`, `<=`, `>`, `>=`, `and`, `or`, parentheses.
_TOKEN = re.compile(r"\s*(\(|\)|==|!=|<=|>=|<|>|\$[A-Za-z_][A-Za-z0-9_]*|[A-Za-z0-9_.\-]+)")
_COMPARE: dict[str, Callable[[str, str], bool]] = {
    "==": lambda a, b: a == b, "!=": lambda a, b: a != b, "<": lambda a, b: a < b,
    "<=": lambda a, b: a <= b, ">": lambda a, b: a > b, ">=": lambda a, b: a >= b}


def evaluate_condition(text: str, *, where: str = "condition") -> bool:
    """Evaluate a package.xml condition for ROS 2 Jazzy (`CONDITION_CONTEXT`); an unknown
    variable is empty, as catkin_pkg has it. `PackageError` if it does not parse."""
    tokens: list[str] = []
    position = 0
    while position < len(text.rstrip()):
        match = _TOKEN.match(text, position)
        if match is None:
            raise PackageError(f"{where}: expected a condition like '$ROS_VERSION == 2', got "
                               f"{text!r} (stuck at {text[position:]!r})")
        tokens.append(match.group(1))
        position = match.end()
    parser = _ConditionParser(tokens, text, where)
    value = parser.disjunction()
    if parser.position != len(tokens):
        parser.fail()
    return value


class _ConditionParser:
    """Recursive descent: `and` binds tighter than `or`, as in catkin_pkg."""

    def __init__(self, tokens: list[str], text: str, where: str) -> None:
        self.tokens, self.text, self.where, self.position = tokens, text, where, 0

    def fail(self) -> None:
        raise PackageError(f"{self.where}: expected a condition like '$ROS_VERSION == 2', "
                           f"got {self.text!r}")

    def take(self) -> str:
        if self.position >= len(self.tokens):
            self.fail()
        self.position += 1
        return self.tokens[self.position - 1]

    def peek(self) -> str | None:
        return self.tokens[self.position] if self.position < len(self.tokens) else None

    def disjunction(self) -> bool:
        value = self.conjunction()
        while self.peek() == "or":
            self.take()
            value = self.conjunction() or value
        return value

    def conjunction(self) -> bool:
        value = self.comparison()
        while self.peek() == "and":
            self.take()
            value = self.comparison() and value
        return value

    def comparison(self) -> bool:
        if self.peek() == "(":
            self.take()
            value = self.disjunction()
            if self.take() != ")":
                self.fail()
            return value
        left, operator, right = self.operand(), self.take(), self.operand()
        if operator not in _COMPARE:
            self.fail()
        return _COMPARE[operator](left, right)

    def operand(self) -> str:
        token = self.take()
        if token in _COMPARE or token in ("(", ")", "and", "or"):
            self.fail()
        if token.startswith("$"):
            return CONDITION_CONTEXT.get(token[1:], "")
        return token
