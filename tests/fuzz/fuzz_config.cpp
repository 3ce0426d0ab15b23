// Fuzz target: parse_config (actors/config.hpp), hermd's YAML configuration
// file (docs/user-guide.md, "Configuration reference"), parsed by yaml-cpp and
// HERM's own field checks.
//
// Properties checked for every input: parse_config is total (a config or
// ec::invalid_config, never an exception or a crash); an error's context
// names the file; a parsed config is complete and consistent (a valid
// module name, one line number per channel, channels and APOs with
// non-empty, unique names, known link kinds, log level, format and
// scheduler). Decode only: configs have no encoder.
//
// Regression seed corpus/config/regression-loadall-comma: a lone ","
// made yaml-cpp 0.7.0's YAML::LoadAll loop for ever (fixed in config.cpp).

#include <cstddef>
#include <cstdint>
#include <string>

#include "actors/config.hpp"
#include "actors/runtime/error.hpp"
#include "channels/link_driver.hpp"
#include "tests/fuzz/fuzz_support.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  std::string text(reinterpret_cast<const char*>(data), size);
  auto cfg = herm::parse_config(text, "fuzz.yaml");
  if (!cfg) {
    HERM_FUZZ_CHECK(herm::is(cfg.error(), herm::ec::invalid_config));
    auto rendered = herm::render(cfg.error());
    HERM_FUZZ_CHECK(rendered.find("fuzz.yaml") != std::string::npos);
    return 0;
  }
  HERM_FUZZ_CHECK(!cfg->name.empty() && cfg->name.size() <= 64);
  HERM_FUZZ_CHECK(cfg->device_lines.size() == cfg->module.devices.size());
  auto& devs = cfg->module.devices;
  for (size_t i = 0; i < devs.size(); ++i) {
    HERM_FUZZ_CHECK(!devs[i].name.empty() && !devs[i].interface.empty());
    HERM_FUZZ_CHECK(herm::find_link_kind(devs[i].kind) != nullptr);
    for (size_t j = 0; j < i; ++j)
      HERM_FUZZ_CHECK(devs[j].name != devs[i].name);
  }
  for (size_t i = 0; i < cfg->apos.size(); ++i) {
    auto& apo = cfg->apos[i];
    HERM_FUZZ_CHECK(!apo.name.empty() && apo.name.size() <= 255);
    HERM_FUZZ_CHECK(!apo.kind.empty());
    for (size_t j = 0; j < i; ++j)
      HERM_FUZZ_CHECK(cfg->apos[j].name != apo.name);
  }
  auto in = [](const std::string& x, std::initializer_list<const char*> xs) {
    for (auto* y : xs)
      if (x == y)
        return true;
    return false;
  };
  HERM_FUZZ_CHECK(in(cfg->log_level,
                     {"trace", "debug", "info", "warn", "error", "off"}));
  HERM_FUZZ_CHECK(in(cfg->log_format, {"text", "json"}));
  HERM_FUZZ_CHECK(in(cfg->scheduler, {"loop", "sharing", "stealing"}));
  return 0;
}
