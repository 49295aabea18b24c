# The cache wall of DESIGN.md, checked over the sources: renderers reach data only through the
# cache and the dataset views, never a store.
#
#   cmake -DROOT=<source dir> -P check_include_wall.cmake
#
# Fails (FATAL_ERROR, listing every offending line) when
# - a file under renderers/ includes a header of storage/, preprocess/, session/, report/ or
#   apps/ (the layers above or beside the renderers' data path), or LMDB or LZ4;
# - a header under core/, fields/, dataset/, cache/ or renderers/ (everything a renderer can
#   include) includes one of storage/, preprocess/, session/, report/ or apps/: so no renderer
#   reaches a store through another header either;
# - a file under cache/ or dataset/ includes storage/ (the cache knows no store);
# - a file outside storage/ includes <lmdb.h> or <lz4.h>.
if(NOT ROOT)
  message(FATAL_ERROR "check_include_wall.cmake needs -DROOT=<source dir>")
endif()

set(violations "")
set(above "storage|preprocess|session|report|apps")

function(scan pattern regex why)
  file(GLOB_RECURSE files RELATIVE "${ROOT}" ${pattern})
  foreach(f ${files})
    file(STRINGS "${ROOT}/${f}" lines REGEX "^[ \t]*#[ \t]*include[ \t]*[<\"]")
    foreach(line ${lines})
      if(line MATCHES "${regex}")
        string(STRIP "${line}" line)
        list(APPEND violations "${f}: ${line} (${why})")
      endif()
    endforeach()
  endforeach()
  set(violations "${violations}" PARENT_SCOPE)
endfunction()

scan("${ROOT}/renderers/*.cpp;${ROOT}/renderers/*.h"
     "[<\"](${above})/|[<\"](lmdb|lz4|lz4hc)\\.h[\">]"
     "renderers reach data only through cache/ and dataset/")
foreach(layer core fields dataset cache renderers)
  scan("${ROOT}/${layer}/*.h" "[<\"](${above})/" "a header a renderer can include must not bring in a store")
endforeach()
scan("${ROOT}/cache/*.cpp;${ROOT}/cache/*.h;${ROOT}/dataset/*.cpp;${ROOT}/dataset/*.h"
     "[<\"]storage/" "the cache reads through PageSource and knows no store")
foreach(layer core fields dataset cache renderers preprocess session report apps bench tests examples)
  scan("${ROOT}/${layer}/*.cpp;${ROOT}/${layer}/*.h" "[<\"](lmdb|lz4|lz4hc)\\.h[\">]"
       "LMDB and LZ4 stay inside storage/*.cpp")
endforeach()

list(LENGTH violations count)
if(count GREATER 0)
  string(REPLACE ";" "\n  " text "${violations}")
  message(FATAL_ERROR "the cache wall is broken in ${count} place(s):\n  ${text}")
endif()
message(STATUS "include wall: holds")
