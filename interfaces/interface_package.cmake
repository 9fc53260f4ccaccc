# faultledger_interface_package(DEPENDENCIES pkg ...): what every package in interfaces/ does.
# Generates the package's msg/, srv/ and action/ definitions (C and Python type support only,
# c_and_python_only.cmake) into the venv's ROS prefix, with the fix the PyPI wheels need
# (pypi_wheels_fix.cmake). A macro, not a function: ament_package() must see the caller's scope.
macro(faultledger_interface_package)
  cmake_parse_arguments(_fl "" "" "DEPENDENCIES" ${ARGN})
  find_package(ament_cmake REQUIRED)
  find_package(rosidl_default_generators REQUIRED)
  foreach(_fl_dep IN LISTS _fl_DEPENDENCIES)
    find_package(${_fl_dep} REQUIRED)
  endforeach()
  file(GLOB _fl_definitions RELATIVE "${CMAKE_CURRENT_SOURCE_DIR}" CONFIGURE_DEPENDS
    msg/*.msg srv/*.srv action/*.action)
  include("${CMAKE_CURRENT_LIST_DIR}/../c_and_python_only.cmake")
  rosidl_generate_interfaces(${PROJECT_NAME} ${_fl_definitions}
    DEPENDENCIES ${_fl_DEPENDENCIES})
  include("${CMAKE_CURRENT_LIST_DIR}/../pypi_wheels_fix.cmake")
  ament_export_dependencies(rosidl_default_runtime)
  ament_package()
endmacro()
