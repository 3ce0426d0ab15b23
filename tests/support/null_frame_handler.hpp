#pragma once

#include "channels/link_driver.hpp"

namespace herm::test {

/// Swallows everything: for a raw station that only sends.
struct null_frame_handler : frame_handler {
  void on_frame(link_addr, const uint8_t*, size_t) override {}
  void on_malformed(link_addr, const char*) override {}
  void on_event(link_event_kind, link_addr, std::string) override {}
  void on_failure(caf::error) override {}
};

} // namespace herm::test
