// Umbrella header of the psc core.
#pragma once

#include "psc/budget.h"
#include "psc/error.h"
#include "psc/hash_grid.h"
#include "psc/mesh.h"
#include "psc/partition.h"
#include "psc/repartition.h"
#include "psc/settings.h"
#include "psc/shapes.h"
#include "psc/types.h"
#include "psc/world.h"
