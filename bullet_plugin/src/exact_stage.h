// Private: the exact stage's implementation lives with its public interface, psc/bullet/exact.h.
#pragma once

#include "psc/bullet/exact.h"
