#pragma once
// A cache header that brings a store to every renderer that includes it.
#include "storage/manifest.h"
