#include "routing/auth.hpp"

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <iterator>
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <openssl/core_names.h>
#include <openssl/crypto.h>
#include <openssl/evp.h>
#include <openssl/params.h>
#include <openssl/rand.h>

#include "channels/hex.hpp"
#include "channels/le_codec.hpp"
#include "routing/error.hpp"

namespace herm {

// -- key files -------------------------------------------------------------------

namespace {

/// Larger key files are refused before reading (hex of 64 bytes is 128).
constexpr off_t max_key_file = 1024;

std::string octal(unsigned mode) {
  char buf[16];
  std::snprintf(buf, sizeof(buf), "%04o", mode & 07777);
  return buf;
}

} // namespace

caf::expected<std::vector<uint8_t>> load_key(const std::string& path) {
  std::vector<uint8_t> key;
  auto err = read_key(path, key);
  if (!err.empty())
    return make_error(ec::invalid_config, err);
  return key;
}

std::string read_key(const std::string& path, std::vector<uint8_t>& key) {
  key.clear();
  auto fail = [&](const std::string& what) {
    return path + ": key file " + what;
  };
  int fd = ::open(path.c_str(), O_RDONLY | O_NOFOLLOW | O_CLOEXEC | O_NOCTTY
                                  | O_NONBLOCK);
  if (fd < 0) {
    auto err = errno;
    if (err == ELOOP)
      return fail("is a symbolic link (name the file itself)");
    return fail(std::string{"cannot be opened: "} + std::strerror(err));
  }
  struct closer {
    int fd;
    ~closer() {
      ::close(fd);
    }
  } guard{fd};
  struct stat st;
  if (::fstat(fd, &st) != 0)
    return fail(std::string{"cannot be examined: "} + std::strerror(errno));
  if (!S_ISREG(st.st_mode))
    return fail("is not a regular file");
  if (st.st_uid != ::geteuid())
    return fail("is owned by uid " + std::to_string(st.st_uid)
                + ", not by this user (uid " + std::to_string(::geteuid())
                + ")");
  if ((st.st_mode & 077) != 0)
    return fail("has mode " + octal(st.st_mode)
                + ": group or others may access it (chmod 600)");
  if (st.st_size > max_key_file)
    return fail("is " + std::to_string(st.st_size) + " bytes, at most "
                + std::to_string(max_key_file));
  std::string text(static_cast<size_t>(st.st_size), '\0');
  size_t got = 0;
  while (got < text.size()) {
    auto n = ::read(fd, &text[got], text.size() - got);
    if (n < 0 && errno == EINTR)
      continue;
    if (n < 0)
      return fail(std::string{"cannot be read: "} + std::strerror(errno));
    if (n == 0)
      break;
    got += static_cast<size_t>(n);
  }
  text.resize(got);
  if (!text.empty() && text.back() == '\n')
    text.pop_back();
  if (!text.empty() && text.back() == '\r')
    text.pop_back();
  for (auto c : text)
    if (hex_digit(c) < 0)
      return fail("must hold hex digits only (e.g. made with "
                  "'openssl rand -hex 32')");
  if (text.size() % 2 != 0)
    return fail("holds an odd number of hex digits");
  auto bytes = text.size() / 2;
  if (bytes < min_key_bytes || bytes > max_key_bytes)
    return fail("holds a key of " + std::to_string(bytes) + " bytes, expected "
                + std::to_string(min_key_bytes) + " to "
                + std::to_string(max_key_bytes));
  key.resize(bytes);
  for (size_t i = 0; i < bytes; ++i)
    key[i] = static_cast<uint8_t>(hex_digit(text[2 * i]) << 4
                                  | hex_digit(text[2 * i + 1]));
  OPENSSL_cleanse(&text[0], text.size());
  return {};
}

// -- policy ----------------------------------------------------------------------

bool data_needs_auth(const auth_config& cfg, module_id dst, uint8_t protocol,
                     const uint8_t* payload, size_t size) {
  if (!cfg.enabled())
    return false;
  if (cfg.data == auth_data::all || dst == broadcast_module)
    return true;
  return protocol == discovery_protocol && size >= 2 && payload != nullptr
         && payload[1] == discovery_answer_kind;
}

// -- results ---------------------------------------------------------------------

namespace {

/// Per auth_result, in enum order: its name, and the counter of auth_stats
/// a verify with that result bumps (challenge_failed is accept_reply's,
/// never verify's).
struct result_row {
  const char* name;
  uint64_t auth_stats::*verified;
};

constexpr result_row result_rows[] = {
  {"ok", &auth_stats::accepted},
  {"truncated", &auth_stats::truncated},
  {"wrong_key_id", &auth_stats::wrong_key_id},
  {"bad_tag", &auth_stats::bad_tag},
  {"replayed", &auth_stats::replayed},
  {"table_full", &auth_stats::table_full},
  {"unknown_index", &auth_stats::unknown_index},
  {"challenge_failed", nullptr},
};

static_assert(std::size(result_rows)
              == static_cast<size_t>(auth_result::challenge_failed) + 1);

} // namespace

const char* to_string(auth_result x) {
  auto i = static_cast<size_t>(x);
  return i < std::size(result_rows) ? result_rows[i].name : "?";
}

// -- authenticator ---------------------------------------------------------------

struct authenticator::impl {
  EVP_MAC* mac = nullptr;
  /// Initialised with the key; duplicated per packet.
  EVP_MAC_CTX* keyed = nullptr;

  ~impl() {
    EVP_MAC_CTX_free(keyed);
    EVP_MAC_free(mac);
  }
};

authenticator::authenticator(auth_config cfg, uint32_t index,
                             random_source random)
  : cfg_(std::move(cfg)),
    index_(index),
    random_(std::move(random)),
    impl_(std::make_unique<impl>()) {
  if (cfg_.tag_bytes != 16)
    cfg_.tag_bytes = 8;
  if (cfg_.max_senders == 0)
    cfg_.max_senders = 1;
  if (!random_)
    random_ = [](uint8_t* out, size_t n) {
      return RAND_bytes(out, static_cast<int>(n)) == 1;
    };
  impl_->mac = EVP_MAC_fetch(nullptr, "HMAC", nullptr);
  if (impl_->mac != nullptr)
    impl_->keyed = EVP_MAC_CTX_new(impl_->mac);
  if (impl_->keyed != nullptr) {
    char digest[] = "SHA256";
    OSSL_PARAM params[] = {
      OSSL_PARAM_construct_utf8_string(OSSL_MAC_PARAM_DIGEST, digest, 0),
      OSSL_PARAM_construct_end(),
    };
    if (EVP_MAC_init(impl_->keyed, cfg_.key.data(), cfg_.key.size(), params)
        != 1) {
      EVP_MAC_CTX_free(impl_->keyed);
      impl_->keyed = nullptr;
    }
  }
}

authenticator::~authenticator() {
  if (!cfg_.key.empty())
    OPENSSL_cleanse(cfg_.key.data(), cfg_.key.size());
}

bool authenticator::mac(uint8_t link, const uint8_t* data, size_t size,
                        std::array<uint8_t, 32>& out) {
  out.fill(0);
  if (impl_->keyed == nullptr)
    return false;
  auto* ctx = EVP_MAC_CTX_dup(impl_->keyed);
  if (ctx == nullptr)
    return false;
  // Pseudo-header: domain string and the link code (RFC 8967 binds the
  // link addresses; see docs/protocol.md for what HERM binds and why).
  static constexpr uint8_t domain[] = {'H', 'E', 'R', 'M', '-', 'A', '1'};
  size_t len = 0;
  bool ok = EVP_MAC_update(ctx, domain, sizeof(domain)) == 1
            && EVP_MAC_update(ctx, &link, 1) == 1
            && EVP_MAC_update(ctx, data, size) == 1
            && EVP_MAC_final(ctx, out.data(), &len, out.size()) == 1
            && len == out.size();
  EVP_MAC_CTX_free(ctx);
  return ok;
}

void authenticator::sign(byte_buffer& packet, uint8_t link) {
  le_writer{packet}.u8(cfg_.key_id).u32(index_).u64(counter_++);
  // Without a working HMAC the tag is zeros, which every receiver refuses
  // (verify refuses whatever it cannot compute).
  std::array<uint8_t, 32> tag;
  mac(link, packet.data(), packet.size(), tag);
  packet.insert(packet.end(), tag.begin(), tag.begin() + cfg_.tag_bytes);
  ++stats_.signed_packets;
}

auth_result authenticator::verify(const uint8_t* data, size_t size,
                                  uint8_t link, time_point now,
                                  size_t& body_size, size_t min_body) {
  auth_trailer t;
  auto res = verify(data, size, link, now, t, min_body);
  if (res == auth_result::ok)
    body_size = t.body_size;
  return res;
}

auth_result authenticator::verify(const uint8_t* data, size_t size,
                                  uint8_t link, time_point now,
                                  auth_trailer& out, size_t min_body) {
  auto count = [&](auth_result r) {
    if (auto counter = result_rows[static_cast<size_t>(r)].verified)
      ++(stats_.*counter);
    return r;
  };
  auto trailer = cfg_.trailer_size();
  if (data == nullptr || size < trailer || size - trailer < min_body)
    return count(auth_result::truncated);
  auto body = size - trailer;
  // The trailer has a fixed size, checked above: the reads cannot fail.
  le_reader t{data, size, body};
  if (t.u8() != cfg_.key_id)
    return count(auth_result::wrong_key_id);
  auto index = t.u32();
  auto pc = t.u64();
  std::array<uint8_t, 32> want;
  if (!mac(link, data, body + auth_head_size, want))
    return count(auth_result::bad_tag);
  if (CRYPTO_memcmp(want.data(), data + body + auth_head_size, cfg_.tag_bytes)
      != 0)
    return count(auth_result::bad_tag);
  out.index = index;
  out.counter = pc;
  out.body_size = body;
  // Only packets with a right tag touch the replay table, so a module
  // without the key can neither fill it nor advance a counter.
  auto i = senders_.find(index);
  if (i != senders_.end()) {
    if (pc <= i->second.counter)
      return count(auth_result::replayed);
    i->second.counter = pc;
    i->second.last = now;
    return count(auth_result::ok);
  }
  // A right tag from an index never heard proves only that someone with
  // the key signed it once: with the challenge, the sender must show it is
  // alive before its index counts.
  if (cfg_.challenge)
    return count(auth_result::unknown_index);
  if (!admit(index, pc, now))
    return count(auth_result::table_full);
  return count(auth_result::ok);
}

bool authenticator::admit(uint32_t index, uint64_t counter, time_point now) {
  auto i = senders_.find(index);
  if (i == senders_.end() && senders_.size() >= cfg_.max_senders) {
    auto oldest = senders_.end();
    for (auto j = senders_.begin(); j != senders_.end(); ++j)
      if (oldest == senders_.end() || j->second.last < oldest->second.last)
        oldest = j;
    if (oldest == senders_.end() || now - oldest->second.last < cfg_.forget_after)
      return false;
    senders_.erase(oldest);
  }
  auto& s = senders_[index];
  // Never lowered (accept_reply for an index known meanwhile).
  s.counter = std::max(s.counter, counter);
  s.last = now;
  return true;
}

// -- challenges ------------------------------------------------------------------

bool authenticator::challenge(uint32_t index, time_point now,
                              challenge_nonce& nonce) {
  auto i = challenges_.find(index);
  if (i != challenges_.end() && now - i->second.sent < cfg_.challenge_interval) {
    ++stats_.challenges_limited;
    return false;
  }
  challenge_nonce fresh;
  if (!random_(fresh.data(), fresh.size())) {
    ++stats_.challenges_limited;
    return false;
  }
  if (i == challenges_.end() && challenges_.size() >= cfg_.max_senders) {
    for (auto j = challenges_.begin(); j != challenges_.end();)
      j = now - j->second.sent > cfg_.challenge_timeout ? challenges_.erase(j)
                                                        : std::next(j);
    if (challenges_.size() >= cfg_.max_senders) {
      auto oldest = challenges_.begin();
      for (auto j = challenges_.begin(); j != challenges_.end(); ++j)
        if (j->second.sent < oldest->second.sent)
          oldest = j;
      challenges_.erase(oldest);
    }
  }
  auto& p = challenges_[index];
  p.nonce = fresh;
  p.sent = now;
  nonce = fresh;
  ++stats_.challenges_sent;
  return true;
}

auth_result authenticator::accept_reply(const auth_trailer& t,
                                        const challenge_nonce& nonce,
                                        time_point now) {
  auto i = challenges_.find(t.index);
  if (i == challenges_.end()) {
    ++stats_.challenges_failed;
    return auth_result::challenge_failed;
  }
  if (now - i->second.sent > cfg_.challenge_timeout) {
    challenges_.erase(i);
    ++stats_.challenges_failed;
    return auth_result::challenge_failed;
  }
  if (CRYPTO_memcmp(i->second.nonce.data(), nonce.data(), nonce.size()) != 0) {
    ++stats_.challenges_failed;
    return auth_result::challenge_failed;
  }
  challenges_.erase(i);
  if (!admit(t.index, t.counter, now)) {
    ++stats_.challenges_failed;
    return auth_result::table_full;
  }
  ++stats_.challenges_passed;
  return auth_result::ok;
}

bool authenticator::may_reply(uint32_t index, time_point now) {
  auto i = replied_.find(index);
  if (i != replied_.end()) {
    if (now - i->second < cfg_.challenge_interval) {
      ++stats_.replies_limited;
      return false;
    }
  } else if (replied_.size() >= cfg_.max_senders) {
    for (auto j = replied_.begin(); j != replied_.end();)
      j = now - j->second >= cfg_.challenge_interval ? replied_.erase(j)
                                                     : std::next(j);
    if (replied_.size() >= cfg_.max_senders) {
      ++stats_.replies_limited;
      return false;
    }
  }
  replied_[index] = now;
  ++stats_.replies;
  return true;
}

} // namespace herm
