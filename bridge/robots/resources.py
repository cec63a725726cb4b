"""Resolve the resource URIs of a URDF (``package://``, ``file://``, paths) to local files.

A ``package://NAME/REST`` URI is looked up in this order, first match wins:

1. ``package_paths`` given explicitly (the daemon's ``--package-path NAME=DIR``): ``DIR``
   is the package's folder, whatever its package.xml says (or if it has none);
2. ``ROS_PACKAGE_PATH`` (``os.pathsep``-separated folders): an entry that is the package
   itself (folder named NAME, or whose package.xml names NAME), else ``ENTRY/NAME``;
3. the ament index: for each prefix of ``AMENT_PREFIX_PATH``, ``PREFIX/share/NAME``.

``file:///abs/path`` (percent-decoded) and absolute paths are used as they are; a relative
path is taken relative to ``base_dir`` (the URDF's folder when it was read from a file),
else to the current directory. Nothing is ever downloaded: ``http(s)://`` is refused.

The environment is read once, when the resolver is made, so one robot load sees one
consistent search path; package folders found are remembered per resolver.

A resolver with ``allowed_roots`` (a robot a client asked for) resolves only to files inside
those folders (symlinks followed); a file outside them and a missing file get the same
`ResourceError`, which names the URI as written and nothing the daemon found, so a client
cannot use a robot's warnings to learn what exists on the daemon's machine.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping, Optional
from urllib.parse import unquote, urlsplit

from bridge.robots.errors import ResourceError

__all__ = ["PackageResolver", "parse_package_path_option"]

_PACKAGE_XML_NAME = re.compile(rb"<name>\s*([^<\s]+)\s*</name>")


def parse_package_path_option(text: str) -> tuple[str, Path]:
    """``"NAME=DIR"`` (a ``--package-path`` option) -> ``(NAME, Path(DIR))``."""
    name, sep, folder = text.partition("=")
    name = name.strip()
    if not sep or not name or not folder.strip() or "/" in name:
        raise ResourceError("--package-path", "NAME=DIR (a package name, '=', a folder)",
                            text)
    return name, Path(folder.strip()).expanduser()


def _package_xml_name(folder: Path) -> Optional[str]:
    try:
        head = (folder / "package.xml").read_bytes()[:65536]
    except OSError:
        return None
    match = _PACKAGE_XML_NAME.search(head)
    return match.group(1).decode(errors="replace") if match else None


def _split_env(value: Optional[str]) -> tuple[Path, ...]:
    return tuple(Path(p) for p in (value or "").split(os.pathsep) if p.strip())


@dataclass
class PackageResolver:
    """Turns URDF resource URIs into existing local files (see the module doc for the order).

    ``package_paths`` maps a package name to its folder; ``base_dir`` anchors relative
    paths. ``ros_package_path`` and ``ament_prefix_path`` default to the environment.
    """

    package_paths: Mapping[str, Path] = field(default_factory=dict)
    base_dir: Optional[Path] = None
    ros_package_path: Optional[tuple[Path, ...]] = None
    ament_prefix_path: Optional[tuple[Path, ...]] = None
    allowed_roots: Optional[tuple[Path, ...]] = None  # None: any file (the operator's robots)
    _found: dict[str, Optional[Path]] = field(default_factory=dict, init=False, repr=False)
    # The allowed roots with their symlinks followed, once per resolver (a robot's load):
    # following them again for each of its files took a third of its resolving.
    _real_roots: tuple[str, ...] = field(default=(), init=False, repr=False)

    def __post_init__(self) -> None:
        self.package_paths = {name: Path(p) for name, p in self.package_paths.items()}
        self._real_roots = tuple(os.path.realpath(root) for root in self.allowed_roots or ())
        if self.ros_package_path is None:
            self.ros_package_path = _split_env(os.environ.get("ROS_PACKAGE_PATH"))
        if self.ament_prefix_path is None:
            self.ament_prefix_path = _split_env(os.environ.get("AMENT_PREFIX_PATH"))

    # ------------------------------------------------------------------ packages

    def find_package(self, name: str) -> Optional[Path]:
        """The folder of package ``name``, or None if no source knows it."""
        if name not in self._found:
            self._found[name] = self._search(name)
        return self._found[name]

    def _search(self, name: str) -> Optional[Path]:
        explicit = self.package_paths.get(name)
        if explicit is not None:
            return explicit  # trusted as given; a wrong folder shows up as missing files
        for entry in self.ros_package_path or ():
            if entry.is_dir() and (entry.name == name or _package_xml_name(entry) == name):
                return entry
            if (entry / name).is_dir():
                return entry / name
        for prefix in self.ament_prefix_path or ():
            share = prefix / "share" / name
            if share.is_dir():
                return share
        return None

    def searched(self, name: str) -> str:
        """A short description of where ``name`` was looked for, for error messages."""
        places = []
        if self.package_paths:
            places.append("package paths " + ", ".join(sorted(self.package_paths)))
        places.append(f"ROS_PACKAGE_PATH ({len(self.ros_package_path or ())} entries)")
        places.append(f"AMENT_PREFIX_PATH ({len(self.ament_prefix_path or ())} prefixes)")
        return (f"no package {name!r} in " + ", ".join(places)
                + f" (give it with --package-path {name}=DIR)")

    # ------------------------------------------------------------------ URIs

    def resolve(self, uri: str) -> Path:
        """The local file ``uri`` names; raises `ResourceError` if it cannot be found."""
        if not uri or not uri.strip():
            raise ResourceError("filename", "a mesh URI or path", "an empty string")
        uri = uri.strip()
        parts = urlsplit(uri)
        scheme = parts.scheme.lower()
        if scheme == "package":
            package = parts.netloc
            relative = unquote(parts.path).lstrip("/")
            if not package or not relative:
                raise ResourceError(uri, "package://PACKAGE/PATH", uri)
            folder = self.find_package(package)
            if folder is None:
                if self.allowed_roots is not None:  # same answer as a refused file
                    raise ResourceError(uri, "an existing file inside a --robot-dir or "
                                        "--package-path folder", repr(uri))
                raise ResourceError(uri, "a known package", self.searched(package))
            path = folder / relative
        elif scheme == "file":
            # file:///abs (netloc empty) or file://host/abs; a relative file://x is a path.
            raw = unquote(parts.netloc + parts.path) if parts.netloc not in ("", "localhost") \
                else unquote(parts.path)
            path = self._anchor(Path(raw))
        elif scheme in ("", ) or (len(scheme) == 1 and os.name == "nt"):
            path = self._anchor(Path(uri))
        else:
            raise ResourceError(uri, "a package://, file:// URI or a local path "
                                "(nothing is downloaded)", f"scheme {scheme}://")
        if self.allowed_roots is not None:
            real = Path(os.path.realpath(path))
            if not path.is_file() or not any(real.is_relative_to(root)
                                             for root in self._real_roots):
                raise ResourceError(uri, "an existing file inside a --robot-dir or "
                                    "--package-path folder", repr(uri))
            return real
        if not path.is_file():
            # Name the resolved path only where it differs from what was asked for.
            where = "" if str(path) == uri else f"{path}: "
            raise ResourceError(uri, "an existing file", f"{where}nothing there"
                                if not path.exists() else f"{where}not a file")
        return path

    def _anchor(self, path: Path) -> Path:
        path = path.expanduser()
        if path.is_absolute():
            return path
        return (self.base_dir or Path.cwd()) / path
