# Injected by build_interfaces.py (CMAKE_PROJECT_INCLUDE) when itt_msgs is built against the
# ROS 2 wheels from PyPI. Those wheels' exported `*__rosidl_generator_py` targets carry the
# include folders of the machine that built them (/opt/python/cpXY-cpXY/...), which do not
# exist here, and CMake refuses imported targets with missing include folders at generate
# time. At the end of the configure step (after every find_package), each such missing
# folder is replaced by this interpreter's own Python or NumPy include folder. The installed
# cmake files are left untouched; a ROS install from apt never has missing folders, so this
# is a no-op there.

function(itt_point_imported_targets_at_this_python)
  get_property(targets DIRECTORY "${CMAKE_SOURCE_DIR}" PROPERTY IMPORTED_TARGETS)
  foreach(target IN LISTS targets)
    get_target_property(dirs ${target} INTERFACE_INCLUDE_DIRECTORIES)
    if(NOT dirs)
      continue()
    endif()
    set(fixed "")
    set(changed FALSE)
    foreach(dir IN LISTS dirs)
      if(NOT dir MATCHES "^\\$<" AND NOT EXISTS "${dir}")
        if(dir MATCHES "numpy/(_core/)?include$")
          set(dir "${ITT_NUMPY_INCLUDE_DIR}")
          set(changed TRUE)
        elseif(dir MATCHES "/include/python3\\.[0-9]+$")
          set(dir "${ITT_PYTHON_INCLUDE_DIR}")
          set(changed TRUE)
        endif()
      endif()
      list(APPEND fixed "${dir}")
    endforeach()
    if(changed)
      set_target_properties(${target} PROPERTIES INTERFACE_INCLUDE_DIRECTORIES "${fixed}")
    endif()
  endforeach()
endfunction()

cmake_language(DEFER DIRECTORY "${CMAKE_SOURCE_DIR}"
  CALL itt_point_imported_targets_at_this_python)
