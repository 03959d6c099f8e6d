// The real system calls.
#include "airground/drivers/camera/v4l2/syscalls.hpp"

#include <fcntl.h>
#include <sys/ioctl.h>
#include <sys/mman.h>
#include <unistd.h>

#include <cerrno>

namespace ag::v4l2 {

int LinuxSyscalls::open(const char* path, int flags) noexcept { return ::open(path, flags); }
int LinuxSyscalls::close(int fd) noexcept { return ::close(fd); }
int LinuxSyscalls::ioctl(int fd, unsigned long request, void* arg) noexcept {
  int r;
  do {
    r = ::ioctl(fd, request, arg);
  } while (r == -1 && errno == EINTR);
  return r;
}
void* LinuxSyscalls::mmap(std::size_t length, int prot, int flags, int fd, off_t offset) noexcept {
  return ::mmap(nullptr, length, prot, flags, fd, offset);
}
int LinuxSyscalls::munmap(void* addr, std::size_t length) noexcept { return ::munmap(addr, length); }
int LinuxSyscalls::epoll_create1(int flags) noexcept { return ::epoll_create1(flags); }
int LinuxSyscalls::epoll_ctl(int epfd, int op, int fd, epoll_event* ev) noexcept { return ::epoll_ctl(epfd, op, fd, ev); }
int LinuxSyscalls::epoll_wait(int epfd, epoll_event* events, int max, int timeout_ms) noexcept {
  return ::epoll_wait(epfd, events, max, timeout_ms);
}

Syscalls& linux_syscalls() noexcept {
  static LinuxSyscalls s;
  return s;
}

}  // namespace ag::v4l2
