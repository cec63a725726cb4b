"""4x4 matrices in mm: numpy by default, `vtkMatrix4x4` when vtk is importable.

Every public call that takes a matrix accepts a numpy array, nested lists, or a
`vtkMatrix4x4` (duck-typed through ``GetElement``, so vtk is never imported just to check).
Every call that returns one returns a (4, 4) float64 numpy array; `to_vtk` converts.
"""

from __future__ import annotations

from typing import Any, Optional

import numpy as np
import numpy.typing as npt

from protocol.conversions import ConversionError, validate_matrix

__all__ = ["MatrixError", "as_numpy", "as_rows", "fill_vtk", "is_vtk_matrix", "to_vtk",
           "vtk_available"]

Matrix = npt.NDArray[np.float64]


class MatrixError(ValueError):
    """A value is not a rigid 4x4 matrix in mm; says what was expected and what came."""


def is_vtk_matrix(value: Any) -> bool:
    return hasattr(value, "GetElement") and hasattr(value, "SetElement")


def as_numpy(value: Any, *, field: str = "matrix", rigid: bool = True) -> Matrix:
    """A (4, 4) float64 copy of `value` (numpy, nested lists or vtkMatrix4x4).
    With `rigid`, refuse NaN, a last row other than 0 0 0 1 and non-orthonormal rotations."""
    if is_vtk_matrix(value):
        out = np.array([[value.GetElement(i, j) for j in range(4)] for i in range(4)],
                       dtype=np.float64)
    else:
        try:
            out = np.array(value, dtype=np.float64)
        except (TypeError, ValueError) as error:
            raise MatrixError(f"{field}: expected a 4x4 matrix (numpy, lists or "
                              f"vtkMatrix4x4), got {type(value).__name__} ({error})") from None
        if out.shape != (4, 4):
            raise MatrixError(f"{field}: expected shape (4, 4), got {out.shape}")
    if rigid:
        try:
            validate_matrix(out, field=field)
        except ConversionError as error:
            raise MatrixError(str(error)) from None
    return out


def as_rows(value: Any, *, field: str = "matrix") -> list[list[float]]:
    """The JSON form the command schema wants: 4 rows of 4 floats (mm)."""
    return [[float(v) for v in row] for row in as_numpy(value, field=field)]


def vtk_available() -> bool:
    try:
        import vtk  # noqa: F401
    except ImportError:
        return False
    return True


def fill_vtk(matrix: Any, target: Any) -> Any:
    """Copy a matrix into an existing vtkMatrix4x4 (what Slicer's getters do)."""
    values = as_numpy(matrix, rigid=False)
    if hasattr(target, "GetClassName") and not isinstance(target, Matrix4x4):
        # VTK's: one call, not 16 (a display's rate)
        target.DeepCopy(values.ravel().tolist())
        return target
    for i in range(4):
        for j in range(4):
            target.SetElement(i, j, float(values[i, j]))
    return target


def to_vtk(matrix: Any, target: Optional[Any] = None) -> Any:
    """A vtkMatrix4x4 holding `matrix`; raises ImportError naming vtk when it is absent."""
    if target is None:
        try:
            import vtk
        except ImportError:
            raise ImportError("to_vtk needs the vtk package (3D Slicer has it; elsewhere "
                              "`pip install vtk`), or use the numpy matrices") from None
        target = vtk.vtkMatrix4x4()
    return fill_vtk(matrix, target)


class Matrix4x4:
    """The part of vtkMatrix4x4's API that scripts written for the reference use
    (`SetElement`, `GetElement`, `Identity`, `DeepCopy`), for Pythons without vtk. It starts
    as the identity, as vtkMatrix4x4 does; `numpy.asarray(m)` gives its values."""

    def __init__(self) -> None:
        self._values = np.eye(4)

    def SetElement(self, i: int, j: int, value: float) -> None:  # noqa: N802
        self._values[i, j] = float(value)

    def GetElement(self, i: int, j: int) -> float:  # noqa: N802
        return float(self._values[i, j])

    def Identity(self) -> None:  # noqa: N802
        self._values = np.eye(4)

    def DeepCopy(self, other: Any) -> None:  # noqa: N802
        self._values = as_numpy(other, rigid=False).copy()

    def __array__(self, dtype: Any = None, copy: Any = None) -> Any:
        return self._values.astype(dtype) if dtype is not None else self._values.copy()

    def __repr__(self) -> str:
        return f"Matrix4x4({self._values.tolist()})"


def blank_matrix() -> Any:
    """A new identity matrix: a vtkMatrix4x4 where vtk is there (3D Slicer), else a
    `Matrix4x4` with the same element API."""
    try:
        import vtk
    except ImportError:
        return Matrix4x4()
    return vtk.vtkMatrix4x4()
