// Failure channel for bad user input (meshes, settings, files): an exception whose message names
// the offending element. Broken internal invariants are asserts; limits hit during a step are
// counters in StepStats, never exceptions.
#pragma once

#include <stdexcept>
#include <string>

namespace psc {

enum class ErrorCode {
  InvalidMesh,      ///< triangles or positions that cannot be used (NaN, index out of range, empty)
  InvalidSettings,  ///< a setting out of its documented range
  InvalidArgument,  ///< an unknown body, a view of the wrong size, ...
  FileError,        ///< a mesh file that cannot be read
};

const char* toString(ErrorCode code);

class Error : public std::runtime_error {
 public:
  Error(ErrorCode code, const std::string& message)
      : std::runtime_error(std::string(toString(code)) + ": " + message), code_(code) {}
  ErrorCode code() const { return code_; }

 private:
  ErrorCode code_;
};

}  // namespace psc
