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
// Known finding (tests/fuzz/crashes/config-loadall-comma.bin, reported, not
// fixed): yaml-cpp 0.7.0's YAML::LoadAll, which parse_config calls, loops for
// ever allocating on some malformed streams (a lone ","; jbeder/yaml-cpp
// issue 1040, fixed upstream by pull request 1319, after 0.8.0). So that the
// fuzzer can look past it, inputs that trigger it are skipped unless the
// environment sets HERM_FUZZ_KNOWN_FINDINGS=1: a bounded pass of yaml-cpp's
// own parser detects them (more documents than the input has bytes).

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <sstream>
#include <string>

#include <yaml-cpp/eventhandler.h>
#include <yaml-cpp/exceptions.h>
#include <yaml-cpp/parser.h>

#include "actors/config.hpp"
#include "actors/runtime/error.hpp"
#include "channels/link_driver.hpp"
#include "tests/fuzz/fuzz_support.hpp"

namespace {

/// Ignores every event: only the number of documents matters.
struct ignore_events : YAML::EventHandler {
  void OnDocumentStart(const YAML::Mark&) override {
  }
  void OnDocumentEnd() override {
  }
  void OnNull(const YAML::Mark&, YAML::anchor_t) override {
  }
  void OnAlias(const YAML::Mark&, YAML::anchor_t) override {
  }
  void OnScalar(const YAML::Mark&, const std::string&, YAML::anchor_t,
                const std::string&) override {
  }
  void OnSequenceStart(const YAML::Mark&, const std::string&, YAML::anchor_t,
                       YAML::EmitterStyle::value) override {
  }
  void OnSequenceEnd() override {
  }
  void OnMapStart(const YAML::Mark&, const std::string&, YAML::anchor_t,
                  YAML::EmitterStyle::value) override {
  }
  void OnMapEnd() override {
  }
};

/// True when YAML::LoadAll would never return on `text`: yaml-cpp's parser
/// keeps reporting documents without consuming input. Every real document
/// takes at least one byte, so more documents than bytes means the loop.
bool loops_in_load_all(const std::string& text) {
  std::istringstream in(text);
  YAML::Parser parser(in);
  ignore_events handler;
  try {
    for (size_t docs = 0; docs <= text.size() + 1; ++docs)
      if (!parser.HandleNextDocument(handler))
        return false;
  } catch (const YAML::Exception&) {
    return false;
  }
  return true;
}

const bool check_known_findings = [] {
  auto* x = std::getenv("HERM_FUZZ_KNOWN_FINDINGS");
  return x != nullptr && std::strcmp(x, "1") == 0;
}();

} // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  std::string text(reinterpret_cast<const char*>(data), size);
  if (!check_known_findings && loops_in_load_all(text))
    return 0;
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
  HERM_FUZZ_CHECK(in(cfg->scheduler, {"sharing", "stealing"}));
  return 0;
}
