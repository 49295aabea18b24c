// A renderer that opens a store directly: check_include_wall.cmake must refuse it.
#include "storage/store.h"
