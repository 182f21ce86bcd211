# evio_add_library(NAME <module> SOURCES ... PUBLIC_DEPS ... PRIVATE_DEPS ...)
#   One static library per module: target evio_<module>, alias evio::<module>, headers in
#   <module>/include/evio/<module>/, C++17, warnings on, installed and exported.
function(evio_add_library)
  cmake_parse_arguments(A "" "NAME" "SOURCES;PUBLIC_DEPS;PRIVATE_DEPS" ${ARGN})
  set(tgt evio_${A_NAME})
  add_library(${tgt} ${A_SOURCES})
  add_library(evio::${A_NAME} ALIAS ${tgt})
  set_target_properties(${tgt} PROPERTIES EXPORT_NAME ${A_NAME} POSITION_INDEPENDENT_CODE ON)
  target_compile_features(${tgt} PUBLIC cxx_std_17)
  target_include_directories(${tgt} PUBLIC
    $<BUILD_INTERFACE:${CMAKE_CURRENT_SOURCE_DIR}/include>
    $<INSTALL_INTERFACE:include>)
  target_compile_options(${tgt} PRIVATE -Wall -Wextra -Wpedantic)
  target_link_libraries(${tgt} PUBLIC ${A_PUBLIC_DEPS} PRIVATE ${A_PRIVATE_DEPS})
  install(TARGETS ${tgt} EXPORT evioTargets ARCHIVE DESTINATION lib LIBRARY DESTINATION lib)
  install(DIRECTORY include/ DESTINATION include)
endfunction()

# evio_add_test(<name> SOURCES a.cc [b.cc] LIBS evio::calib ... [LABELS integration])
#   One small gtest binary per test file; tests discovered individually so ctest -R works per case.
function(evio_add_test name)
  cmake_parse_arguments(A "" "" "SOURCES;LIBS;LABELS" ${ARGN})
  add_executable(${name} ${A_SOURCES})
  target_compile_features(${name} PRIVATE cxx_std_17)
  target_compile_options(${name} PRIVATE -Wall -Wextra)
  target_link_libraries(${name} PRIVATE ${A_LIBS} evio_test_support GTest::gtest GTest::gtest_main)
  set(labels unit)
  if(A_LABELS)
    set(labels ${A_LABELS})
  endif()
  gtest_discover_tests(${name}
    WORKING_DIRECTORY ${PROJECT_SOURCE_DIR}
    PROPERTIES LABELS "${labels}"
    DISCOVERY_TIMEOUT 60)
endfunction()
