#include "psc/error.h"

namespace psc {

const char* toString(ErrorCode code) {
  switch (code) {
    case ErrorCode::InvalidMesh: return "invalid mesh";
    case ErrorCode::InvalidSettings: return "invalid settings";
    case ErrorCode::InvalidArgument: return "invalid argument";
    case ErrorCode::FileError: return "file error";
  }
  return "error";
}

}  // namespace psc
