#include "apps/mcu/sim/eeprom_file.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>

namespace herm::avr_sim {

namespace {

std::string errno_text(const std::string& what) {
  return what + ": " + std::strerror(errno);
}

} // namespace

eeprom_image load_eeprom(const std::string& path, size_t size) {
  eeprom_image img;
  int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) {
    if (errno != ENOENT)
      img.error = errno_text("cannot read --eeprom " + path);
    return img;
  }
  img.found = true;
  img.bytes.resize(size + 1);
  size_t got = 0;
  while (got < img.bytes.size()) {
    auto n = ::read(fd, img.bytes.data() + got, img.bytes.size() - got);
    if (n < 0 && errno == EINTR)
      continue;
    if (n < 0) {
      img.error = errno_text("cannot read --eeprom " + path);
      break;
    }
    if (n == 0)
      break;
    got += static_cast<size_t>(n);
  }
  ::close(fd);
  if (img.error.empty() && got > size)
    img.error = "--eeprom " + path + " holds more than the EEPROM's "
                + std::to_string(size) + " bytes";
  img.bytes.resize(img.error.empty() ? got : 0);
  return img;
}

std::string save_eeprom(const std::string& path, const uint8_t* data, size_t size) {
  auto tmp = path + ".tmp";
  int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0)
    return errno_text("cannot write " + tmp);
  size_t done = 0;
  while (done < size) {
    auto n = ::write(fd, data + done, size - done);
    if (n < 0 && errno == EINTR)
      continue;
    if (n <= 0) {
      auto err = errno_text("cannot write " + tmp);
      ::close(fd);
      ::unlink(tmp.c_str());
      return err;
    }
    done += static_cast<size_t>(n);
  }
  bool synced = ::fsync(fd) == 0;
  auto sync_errno = errno;
  bool closed = ::close(fd) == 0;
  if (!synced || !closed) {
    if (!synced)
      errno = sync_errno;
    auto err = errno_text("cannot write " + tmp);
    ::unlink(tmp.c_str());
    return err;
  }
  if (::rename(tmp.c_str(), path.c_str()) != 0) {
    auto err = errno_text("cannot rename " + tmp + " to " + path);
    ::unlink(tmp.c_str());
    return err;
  }
  return {};
}

} // namespace herm::avr_sim
