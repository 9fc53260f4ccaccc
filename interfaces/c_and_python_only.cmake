# rclpy loads only the C type support (the rosidl_typesupport_c dispatcher, Fast DDS's C type
# support and C introspection) and the Python bindings built on it; nothing in this venv loads
# C++ message code. rosidl_default_generators registers the C++ generators too, and they are
# most of the compile time (docs/performance.md "First run"), so drop them before
# rosidl_generate_interfaces() runs the registered generators. A C++ node that needs these
# interfaces builds them from source in its own ROS workspace, as usual.
list(FILTER AMENT_EXTENSIONS_rosidl_generate_idl_interfaces EXCLUDE REGEX "_cpp:")
