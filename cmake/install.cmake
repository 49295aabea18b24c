# `cmake --install`: the brickyard executable, and a CMake package for back ends built outside
# the tree (find_package(brickyard)): the headers of the renderer interface, the dataset views,
# the cache and what they include, the libraries behind them, and brickyard::module, the target
# a back-end module links (headers and flags; its symbols come from the executable).
include(GNUInstallDirs)
include(CMakePackageConfigHelpers)

add_library(brickyard_module INTERFACE)
# Installed, both <brickyard/cache/page_cache.h> (a module's own includes) and "cache/
# page_cache.h" (the headers' includes of each other) resolve.
target_include_directories(brickyard_module INTERFACE $<BUILD_INTERFACE:${PROJECT_SOURCE_DIR}>
                                                      $<INSTALL_INTERFACE:${CMAKE_INSTALL_INCLUDEDIR}/brickyard>
                                                      $<INSTALL_INTERFACE:${CMAKE_INSTALL_INCLUDEDIR}>)
target_compile_features(brickyard_module INTERFACE cxx_std_20)
target_link_libraries(brickyard_module INTERFACE fmt::fmt TBB::tbb)
add_library(brickyard::module ALIAS brickyard_module)
set_target_properties(brickyard_module PROPERTIES EXPORT_NAME module)
set_target_properties(brickyard PROPERTIES EXPORT_NAME brickyard)

foreach(dir core dataset fields cache renderers/common)
  file(GLOB headers ${PROJECT_SOURCE_DIR}/${dir}/*.h)
  install(FILES ${headers} DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}/brickyard/${dir})
endforeach()

install(TARGETS brickyard EXPORT brickyardTargets RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR})
install(TARGETS brickyard_options brickyard_core brickyard_dataset brickyard_fields brickyard_cache brickyard_render
                brickyard_module
        EXPORT brickyardTargets ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR})
set(BRICKYARD_CMAKE_DIR ${CMAKE_INSTALL_LIBDIR}/cmake/brickyard)
install(EXPORT brickyardTargets NAMESPACE brickyard:: DESTINATION ${BRICKYARD_CMAKE_DIR})
configure_package_config_file(${PROJECT_SOURCE_DIR}/cmake/brickyardConfig.cmake.in
                              ${PROJECT_BINARY_DIR}/brickyardConfig.cmake INSTALL_DESTINATION ${BRICKYARD_CMAKE_DIR})
# A module must come from the brickyard it is loaded into: only the exact version matches.
write_basic_package_version_file(${PROJECT_BINARY_DIR}/brickyardConfigVersion.cmake COMPATIBILITY ExactVersion)
install(FILES ${PROJECT_BINARY_DIR}/brickyardConfig.cmake ${PROJECT_BINARY_DIR}/brickyardConfigVersion.cmake
        DESTINATION ${BRICKYARD_CMAKE_DIR})
