// Error and Result: how fallible calls report what went wrong and where, without exceptions on hot paths.
#pragma once

#include <string>
#include <utility>
#include <variant>

namespace ag {

enum class ErrorCode {
  kInvalidArgument,
  kConfig,
  kIo,
  kPermission,
  kMalformed,
  kUnavailable,
  kTimeout,
  kInternal,
};

struct Error {
  ErrorCode code{ErrorCode::kInternal};
  std::string message;  // names what failed and where, for a person

  static Error make(ErrorCode c, std::string m) { return Error{c, std::move(m)}; }
};

template <typename T>
class [[nodiscard]] Result {
 public:
  Result(T value) : v_(std::move(value)) {}  // NOLINT(google-explicit-constructor)
  Result(Error error) : v_(std::move(error)) {}  // NOLINT(google-explicit-constructor)

  [[nodiscard]] bool ok() const noexcept { return std::holds_alternative<T>(v_); }
  explicit operator bool() const noexcept { return ok(); }
  [[nodiscard]] T& value() & { return std::get<T>(v_); }
  [[nodiscard]] const T& value() const& { return std::get<T>(v_); }
  [[nodiscard]] T&& value() && { return std::get<T>(std::move(v_)); }
  [[nodiscard]] const Error& error() const& { return std::get<Error>(v_); }
  T* operator->() { return &value(); }
  const T* operator->() const { return &value(); }

 private:
  std::variant<T, Error> v_;
};

struct Ok {};
using Status = Result<Ok>;
inline Status ok_status() { return Ok{}; }

}  // namespace ag
