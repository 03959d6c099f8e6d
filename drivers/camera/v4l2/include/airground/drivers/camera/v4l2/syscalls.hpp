// The system calls the V4L2 driver makes, behind one seam: LinuxSyscalls on the robot, a fake device in
// the tests. Same signatures and errno conventions as the C library.
#pragma once

#include <sys/epoll.h>
#include <sys/types.h>

#include <cstddef>

namespace ag::v4l2 {

class Syscalls {
 public:
  Syscalls() = default;
  Syscalls(const Syscalls&) = delete;
  Syscalls& operator=(const Syscalls&) = delete;
  virtual ~Syscalls() = default;
  virtual int open(const char* path, int flags) noexcept = 0;
  virtual int close(int fd) noexcept = 0;
  virtual int ioctl(int fd, unsigned long request, void* arg) noexcept = 0;
  virtual void* mmap(std::size_t length, int prot, int flags, int fd, off_t offset) noexcept = 0;
  virtual int munmap(void* addr, std::size_t length) noexcept = 0;
  virtual int epoll_create1(int flags) noexcept = 0;
  virtual int epoll_ctl(int epfd, int op, int fd, epoll_event* ev) noexcept = 0;
  virtual int epoll_wait(int epfd, epoll_event* events, int max, int timeout_ms) noexcept = 0;
};

// The real thing (ioctl retried on EINTR).
class LinuxSyscalls final : public Syscalls {
 public:
  int open(const char* path, int flags) noexcept override;
  int close(int fd) noexcept override;
  int ioctl(int fd, unsigned long request, void* arg) noexcept override;
  void* mmap(std::size_t length, int prot, int flags, int fd, off_t offset) noexcept override;
  int munmap(void* addr, std::size_t length) noexcept override;
  int epoll_create1(int flags) noexcept override;
  int epoll_ctl(int epfd, int op, int fd, epoll_event* ev) noexcept override;
  int epoll_wait(int epfd, epoll_event* events, int max, int timeout_ms) noexcept override;
};
Syscalls& linux_syscalls() noexcept;

}  // namespace ag::v4l2
