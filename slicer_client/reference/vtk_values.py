"""The Slicer-side values of the reference API: VTK objects where ``vtk`` imports (it always
does in 3D Slicer), else plain objects with the same methods.

`SlicerValues` makes them (``matrix()``, ``int_array()``, ``double_array()``, ``table()``,
``points()``, ``uint8_array()``); the helpers below read any of them, VTK or plain, through
the methods both share, so nothing else needs to know which one it holds.
"""

from __future__ import annotations

from typing import Any, Callable, List, Optional, Sequence, Tuple

from slicer_client.matrices import Matrix4x4

__all__ = ["DoubleArray", "IntArray", "Points", "SlicerValues", "Table", "TypeUInt8Array",
           "array_values", "is_data_array", "is_table", "table_columns"]


class _DataArray:
    """vtkDataArray's value API (a flat list of values in tuples of N components)."""

    _convert: Callable[[Any], Any] = float
    _class_name = "vtkDataArray"

    def __init__(self) -> None:
        self._values: List[Any] = []
        self._components = 1
        self._name: Optional[str] = None

    def GetClassName(self) -> str:  # noqa: N802
        return self._class_name

    def IsA(self, name: str) -> bool:  # noqa: N802
        return name in (self._class_name, "vtkDataArray", "vtkAbstractArray", "vtkObject")

    def SetName(self, name: Optional[str]) -> None:  # noqa: N802
        self._name = name

    def GetName(self) -> Optional[str]:  # noqa: N802
        return self._name

    def SetNumberOfComponents(self, n: int) -> None:  # noqa: N802
        self._components = max(1, int(n))

    def GetNumberOfComponents(self) -> int:  # noqa: N802
        return self._components

    def SetNumberOfValues(self, n: int) -> None:  # noqa: N802
        n = int(n)
        zero = self._convert(0)
        self._values = (self._values + [zero] * n)[:n]

    def GetNumberOfValues(self) -> int:  # noqa: N802
        return len(self._values)

    def SetNumberOfTuples(self, n: int) -> None:  # noqa: N802
        self.SetNumberOfValues(int(n) * self._components)

    def GetNumberOfTuples(self) -> int:  # noqa: N802
        return len(self._values) // self._components

    def SetValue(self, i: int, value: Any) -> None:  # noqa: N802
        self._values[int(i)] = self._convert(value)

    def GetValue(self, i: int) -> Any:  # noqa: N802
        return self._values[int(i)]

    def InsertValue(self, i: int, value: Any) -> None:  # noqa: N802
        if int(i) >= len(self._values):
            self.SetNumberOfValues(int(i) + 1)
        self.SetValue(i, value)

    def InsertNextValue(self, value: Any) -> int:  # noqa: N802
        self._values.append(self._convert(value))
        return len(self._values) - 1

    def GetTuple(self, i: int) -> Tuple[float, ...]:  # noqa: N802
        n = self._components
        return tuple(float(v) for v in self._values[int(i) * n:(int(i) + 1) * n])

    def Initialize(self) -> None:  # noqa: N802
        self._values = []

    def DeepCopy(self, other: Any) -> None:  # noqa: N802
        self._values = [self._convert(v) for v in array_values(other)]
        self._components = int(other.GetNumberOfComponents())

    def __repr__(self) -> str:
        return f"{self._class_name}({self._values})"


class IntArray(_DataArray):
    _convert = int
    _class_name = "vtkIntArray"


class DoubleArray(_DataArray):
    _convert = float
    _class_name = "vtkDoubleArray"


class TypeUInt8Array(_DataArray):
    _class_name = "vtkTypeUInt8Array"

    @staticmethod
    def _convert(value: Any) -> int:
        byte = int(value)
        if not 0 <= byte <= 255:
            raise ValueError(f"vtkTypeUInt8Array: expected a value in 0..255, got {value!r}")
        return byte


class Table:
    """vtkTable as the reference uses it: columns of equal length (`AddColumn`), read and
    written as ``GetValue(row, column)`` / ``SetValue(row, column, value)``."""

    def __init__(self) -> None:
        self._columns: List[_DataArray] = []

    def GetClassName(self) -> str:  # noqa: N802
        return "vtkTable"

    def AddColumn(self, column: Any) -> None:  # noqa: N802
        self._columns.append(column)

    def GetNumberOfColumns(self) -> int:  # noqa: N802
        return len(self._columns)

    def GetNumberOfRows(self) -> int:  # noqa: N802
        return self._columns[0].GetNumberOfTuples() if self._columns else 0

    def SetNumberOfRows(self, n: int) -> None:  # noqa: N802
        for column in self._columns:
            column.SetNumberOfTuples(n)

    def GetColumn(self, i: int) -> Any:  # noqa: N802
        return self._columns[int(i)]

    def GetValue(self, row: int, column: int) -> Any:  # noqa: N802
        return self._columns[int(column)].GetValue(int(row))

    def SetValue(self, row: int, column: int, value: Any) -> None:  # noqa: N802
        self._columns[int(column)].SetValue(int(row), value)

    def DeepCopy(self, other: Any) -> None:  # noqa: N802
        self._columns = []
        for i in range(other.GetNumberOfColumns()):
            column = type(other.GetColumn(i))()
            column.DeepCopy(other.GetColumn(i))
            self._columns.append(column)

    def __repr__(self) -> str:
        return f"vtkTable({[array_values(c) for c in self._columns]})"


class Points:
    """vtkPoints' point API: 3-D points (mm)."""

    def __init__(self) -> None:
        self._points: List[Tuple[float, float, float]] = []

    def GetClassName(self) -> str:  # noqa: N802
        return "vtkPoints"

    def GetNumberOfPoints(self) -> int:  # noqa: N802
        return len(self._points)

    def SetNumberOfPoints(self, n: int) -> None:  # noqa: N802
        self._points = (self._points + [(0.0, 0.0, 0.0)] * int(n))[:int(n)]

    def InsertNextPoint(self, x: float, y: float = 0.0, z: float = 0.0) -> int:  # noqa: N802
        self._points.append(_xyz(x, y, z))
        return len(self._points) - 1

    def SetPoint(self, i: int, x: float, y: float = 0.0, z: float = 0.0) -> None:  # noqa: N802
        self._points[int(i)] = _xyz(x, y, z)

    def GetPoint(self, i: int) -> Tuple[float, float, float]:  # noqa: N802
        return self._points[int(i)]

    def Reset(self) -> None:  # noqa: N802
        self._points = []

    def Allocate(self, n: int) -> None:  # noqa: N802
        pass  # a list grows by itself

    def DeepCopy(self, other: Any) -> None:  # noqa: N802
        self._points = [_xyz(*other.GetPoint(i)) for i in range(other.GetNumberOfPoints())]


def _xyz(x: Any, y: float, z: float) -> Tuple[float, float, float]:
    if isinstance(x, (tuple, list)):  # InsertNextPoint((x, y, z)) as VTK's Python takes it
        x, y, z = x
    return (float(x), float(y), float(z))


class SlicerValues:
    """Makes the reference's values: VTK's where `vtk` is given or imports, else plain."""

    def __init__(self, vtk: Any = None) -> None:
        """`vtk`: the vtk module, False for plain objects, None to import it if present."""
        if vtk is None:
            try:
                import vtk as imported
            except ImportError:
                imported = False
            vtk = imported
        self.vtk = vtk or None

    def matrix(self) -> Any:
        return self.vtk.vtkMatrix4x4() if self.vtk else Matrix4x4()

    def int_array(self) -> Any:
        return self.vtk.vtkIntArray() if self.vtk else IntArray()

    def double_array(self) -> Any:
        return self.vtk.vtkDoubleArray() if self.vtk else DoubleArray()

    def uint8_array(self) -> Any:
        return self.vtk.vtkTypeUInt8Array() if self.vtk else TypeUInt8Array()

    def table(self) -> Any:
        return self.vtk.vtkTable() if self.vtk else Table()

    def points(self) -> Any:
        return self.vtk.vtkPoints() if self.vtk else Points()

    def filled_array(self, values: Sequence[Any], *, integer: bool) -> Any:
        array = self.int_array() if integer else self.double_array()
        array.SetNumberOfValues(len(values))
        for i, value in enumerate(values):
            array.SetValue(i, int(value) if integer else float(value))
        return array


def is_data_array(value: Any) -> bool:
    return hasattr(value, "GetNumberOfValues") and hasattr(value, "GetValue")


def is_table(value: Any) -> bool:
    return hasattr(value, "GetNumberOfColumns") and hasattr(value, "GetColumn")


def array_values(array: Any) -> List[Any]:
    """The values of a vtk or plain data array, in order."""
    return [array.GetValue(i) for i in range(array.GetNumberOfValues())]


def table_columns(table: Any) -> List[List[Any]]:
    """The columns of a vtk or plain table, each a list of its values."""
    return [array_values(table.GetColumn(i)) for i in range(table.GetNumberOfColumns())]
