# Finds HACD (Khaled Mamou's hierarchical approximate convex decomposition) as shipped by
# Debian's libbullet-extras-dev: header <HACD/hacdHACD.h> under include/bullet, library libHACD.
# HACD computes in double whatever Bullet's precision is, so the single-precision build is used.
find_path(HACD_INCLUDE_DIR NAMES HACD/hacdHACD.h PATH_SUFFIXES bullet)
find_library(HACD_LIBRARY NAMES HACD)
include(FindPackageHandleStandardArgs)
find_package_handle_standard_args(HACD REQUIRED_VARS HACD_LIBRARY HACD_INCLUDE_DIR)
if(HACD_FOUND AND NOT TARGET HACD::HACD)
  add_library(HACD::HACD UNKNOWN IMPORTED)
  # HACD's headers are third-party: include them as system headers so their warnings stay out.
  set_target_properties(HACD::HACD PROPERTIES IMPORTED_LOCATION "${HACD_LIBRARY}")
  set_property(TARGET HACD::HACD PROPERTY INTERFACE_SYSTEM_INCLUDE_DIRECTORIES "${HACD_INCLUDE_DIR}/HACD")
  set_property(TARGET HACD::HACD PROPERTY INTERFACE_INCLUDE_DIRECTORIES "${HACD_INCLUDE_DIR}/HACD")
endif()
mark_as_advanced(HACD_INCLUDE_DIR HACD_LIBRARY)
