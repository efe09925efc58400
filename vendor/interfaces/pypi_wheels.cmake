# Included by setup.py (CMAKE_PROJECT_INCLUDE) in every interface package it builds
# with the ROS 2 Jazzy wheels from PyPI, whose exported *__rosidl_generator_py targets
# name the include folders of the machine that built them (/opt/python/...). Deferred
# to the end of the package's CMakeLists.txt, when its find_package() calls have made
# those targets, and before generation reads them: point them at this interpreter's.
find_package(Python3 REQUIRED COMPONENTS Interpreter Development.Module NumPy)

function(_panel_deploy_pypi_include_dirs)
  get_property(_imported DIRECTORY "${CMAKE_SOURCE_DIR}" PROPERTY IMPORTED_TARGETS)
  foreach(_target IN LISTS _imported)
    if(_target MATCHES "__rosidl_generator_py$")
      set_target_properties(${_target} PROPERTIES
        INTERFACE_INCLUDE_DIRECTORIES "${Python3_INCLUDE_DIRS};${Python3_NumPy_INCLUDE_DIRS}")
    endif()
  endforeach()
endfunction()
cmake_language(DEFER DIRECTORY "${CMAKE_SOURCE_DIR}" CALL _panel_deploy_pypi_include_dirs)
