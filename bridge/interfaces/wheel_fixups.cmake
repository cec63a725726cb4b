# Included by `slicer-ros2-bridge build-interfaces` after the project() of the package it
# builds (CMAKE_PROJECT_INCLUDE), so that any interface package builds against the ROS 2
# PyPI wheels unchanged.
#
# The wheels export CMake targets whose include directories name the wheel builder's paths
# (/opt/python/cpXY-cpXY/...), which do not exist here; CMake's generate step rejects them.
# At the end of the package's CMakeLists (a deferred call: every find_package has run by
# then), keep only the directories that exist; generator expressions are left alone.
function(_slicer_ros2_bridge_drop_missing_include_dirs)
  get_property(_targets DIRECTORY "${CMAKE_SOURCE_DIR}" PROPERTY IMPORTED_TARGETS)
  foreach(_target IN LISTS _targets)
    get_target_property(_dirs ${_target} INTERFACE_INCLUDE_DIRECTORIES)
    if(NOT _dirs)
      continue()
    endif()
    set(_kept "")
    foreach(_dir IN LISTS _dirs)
      if(_dir MATCHES "^\\$<" OR EXISTS "${_dir}")
        list(APPEND _kept "${_dir}")
      endif()
    endforeach()
    set_target_properties(${_target} PROPERTIES INTERFACE_INCLUDE_DIRECTORIES "${_kept}")
  endforeach()
endfunction()

# Once per build, for the top-level project only.
if(CMAKE_CURRENT_SOURCE_DIR STREQUAL CMAKE_SOURCE_DIR
   AND NOT DEFINED _SLICER_ROS2_BRIDGE_FIXUPS_DEFERRED)
  set(_SLICER_ROS2_BRIDGE_FIXUPS_DEFERRED TRUE)
  cmake_language(DEFER DIRECTORY "${CMAKE_SOURCE_DIR}"
                 CALL _slicer_ros2_bridge_drop_missing_include_dirs)
endif()
