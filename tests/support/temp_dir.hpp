#pragma once

// A temporary directory for one test, removed with everything in it when
// the object goes away.

#include <stdlib.h>

#include <filesystem>
#include <string>

namespace herm::test {

class temp_dir {
public:
  /// `prefix` names the directory: /tmp/PREFIX-XXXXXX.
  explicit temp_dir(const std::string& prefix = "herm") {
    std::string tmpl = "/tmp/" + prefix + "-XXXXXX";
    auto* p = ::mkdtemp(tmpl.data());
    path_ = p != nullptr ? p : "";
  }

  temp_dir(const temp_dir&) = delete;
  temp_dir& operator=(const temp_dir&) = delete;

  ~temp_dir() {
    std::error_code ec;
    if (!path_.empty())
      std::filesystem::remove_all(path_, ec);
  }

  /// Empty when the directory could not be created.
  const std::string& path() const {
    return path_;
  }

private:
  std::string path_;
};

} // namespace herm::test
