// Failure channel for bad user input (meshes, settings, files): an exception whose message names
// the offending element. Broken internal invariants are asserts; limits hit during a step are
// counters in StepStats, never exceptions.
#pragma once

#include <cstdint>
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
  static constexpr std::uint32_t kNoBody = 0xFFFFFFFFu;  ///< psc::kInvalidBody
  Error(ErrorCode code, const std::string& message, std::uint32_t body = kNoBody)
      : std::runtime_error(std::string(toString(code)) + ": " + message), code_(code), message_(message), body_(body) {}
  ErrorCode code() const { return code_; }
  /// what() without the code's prefix.
  const std::string& message() const { return message_; }
  /// The body (a SensorWorld's BodyId) whose input the error is about, when SensorWorld::step()
  /// knows it (one body's positions became non-finite, say), so that a caller can leave that body
  /// out and step the others; kNoBody otherwise.
  std::uint32_t body() const { return body_; }

 private:
  ErrorCode code_;
  std::string message_;
  std::uint32_t body_;
};

}  // namespace psc
