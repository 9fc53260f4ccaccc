# The ROS 2 Jazzy wheels on PyPI export *__rosidl_generator_py targets whose include
# directories point at the wheel build host (/opt/python/cp311-cp311/...), which makes the
# CMake generate step fail. Point them at this interpreter's Python and NumPy headers.
find_package(Python3 REQUIRED COMPONENTS Interpreter Development.Module NumPy)
get_directory_property(_imported_targets IMPORTED_TARGETS)
foreach(_t IN LISTS _imported_targets)
  get_target_property(_inc "${_t}" INTERFACE_INCLUDE_DIRECTORIES)
  if(_inc AND "${_inc}" MATCHES "/opt/python/")
    set_target_properties("${_t}" PROPERTIES
      INTERFACE_INCLUDE_DIRECTORIES "${Python3_INCLUDE_DIRS};${Python3_NumPy_INCLUDE_DIRS}")
  endif()
endforeach()
