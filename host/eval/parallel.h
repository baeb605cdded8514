// The evaluation's parallel loop and thread count, from host/util.
#pragma once

#include "host/util/parallel_for.h"
#include "host/util/thread_pool.h"

namespace imr::eval {

// Threads to use for `requested` (<= 0: the cores of the process's affinity mask).
using util::ResolveThreads;
using util::ParallelFor;

}  // namespace imr::eval
