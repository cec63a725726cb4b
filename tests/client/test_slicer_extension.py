"""The Slicer extension's build files, configured by CMake against a stand-in for Slicer.

3D Slicer cannot be built here, so `SlicerConfig.cmake` below stands in for it: it defines
the macros the extension calls (`slicerMacroBuildScriptedModule`, `ctkMacroCompilePythonScript`,
`slicer_add_python_unittest`) to check and record their arguments, nothing more. What this
proves: the CMake files parse, every file they name exists, the module ships its icon, and
the packages the module imports (every .py of protocol/ and slicer_client/) are installed
with it. What it cannot prove: that Slicer's real macros build it (see slicer_client/README.md).
"""

from __future__ import annotations

import json
import shutil
import struct
import subprocess
from pathlib import Path

import pytest

pytestmark = pytest.mark.integration  # starts processes

REPO = Path(__file__).resolve().parents[2]
MODULE = REPO / "slicer_client" / "slicer_module" / "ROS2Bridge"

STAND_IN = r'''
set(Slicer_USE_FILE ${CMAKE_CURRENT_LIST_DIR}/UseSlicer.cmake)
set(Slicer_EXTENSION_GENERATE_CONFIG ${CMAKE_CURRENT_LIST_DIR}/Empty.cmake)
set(Slicer_EXTENSION_CPACK ${CMAKE_CURRENT_LIST_DIR}/Empty.cmake)
set(Slicer_QTSCRIPTEDMODULES_LIB_DIR lib/Slicer/qt-scripted-modules)
set(Slicer_INSTALL_QTSCRIPTEDMODULES_LIB_DIR lib/Slicer/qt-scripted-modules)
'''

USE_SLICER = r'''
function(_record kind)
  file(APPEND ${CMAKE_BINARY_DIR}/recorded.txt "${kind}\n")
endfunction()
function(_check_files)
  foreach(f ${ARGN})
    if(NOT EXISTS ${CMAKE_CURRENT_SOURCE_DIR}/${f})
      message(FATAL_ERROR "missing file ${CMAKE_CURRENT_SOURCE_DIR}/${f}")
    endif()
  endforeach()
endfunction()
macro(slicerMacroBuildScriptedModule)
  cmake_parse_arguments(M "WITH_GENERIC_TESTS;WITH_SUBDIR" "NAME" "SCRIPTS;RESOURCES" ${ARGN})
  if(M_UNPARSED_ARGUMENTS)
    message(FATAL_ERROR "unknown arguments: ${M_UNPARSED_ARGUMENTS}")
  endif()
  _check_files(${M_SCRIPTS} ${M_RESOURCES})
  _record("module ${M_NAME}")
  foreach(f ${M_SCRIPTS})
    _record("module-script ${f}")
  endforeach()
  foreach(f ${M_RESOURCES})
    _record("module-resource ${f}")
  endforeach()
endmacro()
macro(ctkMacroCompilePythonScript)
  cmake_parse_arguments(C "NO_INSTALL_SUBDIR;GLOBAL_TARGET"
    "TARGET_NAME;DESTINATION_DIR;INSTALL_DIR;SOURCE_DIR" "SCRIPTS;RESOURCES" ${ARGN})
  _check_files(${C_SCRIPTS})
  foreach(f ${C_SCRIPTS})
    _record("package-script ${f}")
  endforeach()
endmacro()
macro(SlicerMacroBuildModuleMRML)
  cmake_parse_arguments(L "DISABLE_WRAP_PYTHON" "NAME;EXPORT_DIRECTIVE;FOLDER"
    "SRCS;INCLUDE_DIRECTORIES;TARGET_LIBRARIES" ${ARGN})
  if(L_UNPARSED_ARGUMENTS)
    message(FATAL_ERROR "unknown arguments: ${L_UNPARSED_ARGUMENTS}")
  endif()
  _record("mrml-library ${L_NAME} ${L_EXPORT_DIRECTIVE}")
  foreach(f ${L_SRCS})
    get_filename_component(class ${f} NAME_WE)
    file(READ ${f} source)
    string(REPLACE ".cxx" ".h" header ${f})
    file(READ ${header} header_text)
    string(REGEX MATCH "public ([A-Za-z0-9]+)" base "${header_text}")
    _record("mrml-class ${class} ${CMAKE_MATCH_1}")
  endforeach()
endmacro()
macro(slicer_add_python_unittest)
  cmake_parse_arguments(T "" "SCRIPT" "" ${ARGN})
  _check_files(${T_SCRIPT})
  _record("unittest ${T_SCRIPT}")
endmacro()
_record("depends ${EXTENSION_DEPENDS}")
_record("category ${EXTENSION_CATEGORY}")
'''


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> list[str]:
    cmake = shutil.which("cmake")
    if cmake is None or shutil.which("cc") is None:
        pytest.skip("needs cmake and a C compiler to configure the extension's CMake files")
    slicer = tmp_path_factory.mktemp("slicer-stand-in")
    (slicer / "SlicerConfig.cmake").write_text(STAND_IN)
    (slicer / "UseSlicer.cmake").write_text(USE_SLICER)
    (slicer / "Empty.cmake").write_text("")
    build = tmp_path_factory.mktemp("extension-build")
    run = subprocess.run([cmake, "-S", str(REPO), "-B", str(build), f"-DSlicer_DIR={slicer}",
                          "-DBUILD_TESTING=ON"], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]
    return (build / "recorded.txt").read_text().splitlines()


def test_the_module_is_built_with_its_icon_and_its_test(recorded: list[str]) -> None:
    assert "module ROS2Bridge" in recorded
    assert "module-script ROS2Bridge.py" in recorded
    assert "module-resource Resources/Icons/ROS2Bridge.png" in recorded
    assert "module-resource Resources/UI/ROS2Bridge.ui" in recorded
    # The module's code package ships with it: every file of ROS2BridgeLib, nothing else.
    lib = {f"module-script ROS2BridgeLib/{path.name}"
           for path in (MODULE / "ROS2BridgeLib").glob("*.py")}
    assert lib == {line for line in recorded if line.startswith("module-script ROS2BridgeLib/")}
    assert "unittest ROS2Bridge.py" in recorded


def test_every_module_the_slicer_module_imports_ships_with_it(recorded: list[str]) -> None:
    shipped = {line.split(" ", 1)[1] for line in recorded if line.startswith("package-script")}
    expected = {str(path.relative_to(REPO)) for folder in ("protocol", "slicer_client")
                for path in (REPO / folder).rglob("*.py")
                if "slicer_module" not in path.parts}
    assert shipped == expected
    assert "slicer_client/__init__.py" in shipped and "protocol/framing.py" in shipped


def test_it_depends_on_slicer_openigtlink_in_cmake_and_in_the_index_entry(
        recorded: list[str]) -> None:
    assert "depends SlicerOpenIGTLink" in recorded
    entry = json.loads((REPO / "slicer_client/slicer_module/SlicerROS2Bridge.json").read_text())
    # Required by Slicer's slicer-extension-catalog-entry-schema-v1.0.2.json.
    assert {"$schema", "category", "scm_url"} <= set(entry)
    assert entry["$schema"].endswith("slicer-extension-catalog-entry-schema-v1.0.2.json#")
    assert entry["build_dependencies"] == ["SlicerOpenIGTLink"]
    assert f"category {entry['category']}" in recorded


def test_the_mrml_library_has_the_reference_node_classes(recorded: list[str]) -> None:
    assert ("mrml-library vtkSlicerROS2BridgeModuleMRML "
            "VTK_SLICER_ROS2BRIDGE_MODULE_MRML_EXPORT") in recorded
    classes = dict(line.split(" ")[1:] for line in recorded if line.startswith("mrml-class"))
    # The reference's bases, each deriving from the MRML class it does in SlicerROS2.
    assert classes["vtkMRMLROS2NodeNode"] == "vtkMRMLNode"
    assert classes["vtkMRMLROS2Tf2LookupNode"] == "vtkMRMLLinearTransformNode"
    assert classes["vtkMRMLROS2SubscriberStringNode"] == "vtkMRMLROS2SubscriberNode"
    assert classes["vtkMRMLROS2PublisherPoseStampedNode"] == "vtkMRMLROS2PublisherNode"
    assert classes["vtkMRMLROS2ServiceClientSpawnNode"] == "vtkMRMLROS2ServiceClientNode"
    assert len(classes) == 10 + 20 + 19 + 18


def test_the_icon_is_a_128_pixel_png() -> None:
    data = (MODULE / "Resources/Icons/ROS2Bridge.png").read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    width, height = struct.unpack(">II", data[16:24])
    assert (width, height) == (128, 128)
