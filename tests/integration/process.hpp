// Runs a program as a child process with extra environment, capturing stdout and stderr (test helper).
#pragma once

#include <sys/types.h>

#include <string>
#include <vector>

namespace ag::test {

struct ProcessResult {
  int exit_code{-1};  // -1 when killed by a signal
  int signal{0};
  std::string out;
  std::string err;
};

class Process {
 public:
  Process(const std::vector<std::string>& argv, const std::vector<std::string>& env_extra = {});
  ~Process();
  [[nodiscard]] pid_t pid() const { return pid_; }
  void send_signal(int sig) const;
  // Waits up to timeout_s, killing the child after that (and reporting it).
  ProcessResult wait(double timeout_s);

 private:
  pid_t pid_{-1};
  int out_fd_{-1};
  int err_fd_{-1};
};

ProcessResult run(const std::vector<std::string>& argv, double timeout_s = 20.0,
                  const std::vector<std::string>& env_extra = {});
std::string binary_dir();
std::string source_dir();

}  // namespace ag::test
