// Umbrella header of psc::bullet, the Bullet 3.24 soft-body plugin of psc.
#pragma once

#include "psc/bullet/exact.h"
#include "psc/bullet/memory.h"
#include "psc/bullet/plugin.h"
#include "psc/bullet/precision.h"
#include "psc/bullet/settings.h"
#include "psc/bullet/solver.h"
#include "psc/bullet/stats.h"
