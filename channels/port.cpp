#include "channels/port.hpp"

#include "channels/error.hpp"

namespace herm {

// -- packet_port ---------------------------------------------------------------

packet_port::~packet_port() = default;

size_t packet_port::expire(time_point) {
  return 0;
}

std::optional<packet_port::time_point> packet_port::next_deadline() const {
  return std::nullopt;
}

void packet_port::add_stats(channel_stats&) const {
  // nop
}

size_t packet_port::frames_for(size_t) const {
  return 1;
}

uint8_t packet_port::lane(link_addr, uint8_t) const {
  return 0;
}

void packet_port::flush() {
  // nop
}

bool packet_port::congested() const {
  return false;
}

bool packet_port::next_packet(byte_buffer&) {
  return false;
}

// -- port_decorator ------------------------------------------------------------

port_decorator::port_decorator(std::unique_ptr<packet_port> inner)
  : inner_(std::move(inner)) {
  // nop
}

uint32_t port_decorator::max_packet() const {
  return inner_->max_packet();
}

caf::expected<size_t> port_decorator::send(link_addr dst, uint8_t priority,
                                           const uint8_t* data, size_t size) {
  return inner_->send(dst, priority, data, size);
}

packet_port::rx port_decorator::receive(link_addr src, uint8_t lane,
                                        const uint8_t* data, size_t size,
                                        time_point now, byte_buffer& out) {
  return inner_->receive(src, lane, data, size, now, out);
}

uint8_t port_decorator::lane(link_addr dst, uint8_t priority) const {
  return inner_->lane(dst, priority);
}

size_t port_decorator::expire(time_point now) {
  return inner_->expire(now);
}

std::optional<packet_port::time_point> port_decorator::next_deadline() const {
  return inner_->next_deadline();
}

void port_decorator::add_stats(channel_stats& st) const {
  inner_->add_stats(st);
}

size_t port_decorator::frames_for(size_t size) const {
  return inner_->frames_for(size);
}

caf::expected<size_t> port_decorator::send_frame(link_addr dst,
                                                 uint8_t priority,
                                                 const uint8_t* data,
                                                 size_t size) {
  return inner_->send_frame(dst, priority, data, size);
}

void port_decorator::flush() {
  inner_->flush();
}

bool port_decorator::congested() const {
  return inner_->congested();
}

bool port_decorator::next_packet(byte_buffer& out) {
  return inner_->next_packet(out);
}

// -- frame_port ----------------------------------------------------------------

frame_port::frame_port(link_driver_ptr driver, frame_writer writer)
  : driver_(std::move(driver)), writer_(std::move(writer)) {
  // nop
}

uint32_t frame_port::max_packet() const {
  return driver_->profile().mtu;
}

caf::expected<size_t> frame_port::send(link_addr dst, uint8_t priority,
                                       const uint8_t* data, size_t size) {
  if (size > driver_->profile().mtu)
    return make_error(ec::packet_too_large,
                      std::to_string(size) + " bytes exceed the MTU of "
                        + std::to_string(driver_->profile().mtu));
  return send_frame(dst, priority, data, size);
}

caf::expected<size_t> frame_port::send_frame(link_addr dst, uint8_t priority,
                                             const uint8_t* data,
                                             size_t size) {
  if (auto err = writer_ ? writer_(dst, priority, data, size)
                         : driver_->send(dst, data, size, priority))
    return err;
  return size_t{1};
}

packet_port::rx frame_port::receive(link_addr, uint8_t, const uint8_t* data,
                                    size_t size, time_point, byte_buffer& out) {
  out.assign(data, data + size);
  return rx::packet;
}

uint8_t frame_port::lane(link_addr dst, uint8_t priority) const {
  return driver_->lane(dst, priority);
}

// -- fragmenting_port ------------------------------------------------------------

fragmenting_port::fragmenting_port(std::unique_ptr<packet_port> inner,
                                   uint32_t inner_mtu,
                                   reassembly_limits limits)
  : port_decorator(std::move(inner)),
    fragmenter_(inner_mtu),
    reassembler_(limits) {
  // nop
}

uint32_t fragmenting_port::max_packet() const {
  return static_cast<uint32_t>(reassembler_.limits().max_packet);
}

caf::expected<size_t> fragmenting_port::send(link_addr dst, uint8_t priority,
                                             const uint8_t* data,
                                             size_t size) {
  if (size > reassembler_.limits().max_packet)
    return make_error(ec::packet_too_large,
                      std::to_string(size) + " bytes exceed the channel's "
                        "maximum packet of "
                        + std::to_string(reassembler_.limits().max_packet));
  size_t frames = 0;
  caf::error err;
  auto lane = inner_->lane(dst, priority);
  fragmenter_.split(dst, lane, data, size, [&](const uint8_t* frame, size_t len) {
    if (err)
      return;
    auto res = inner_->send(dst, priority, frame, len);
    if (res)
      frames += *res;
    else
      err = std::move(res.error());
  });
  if (err)
    return err;
  return frames;
}

packet_port::rx fragmenting_port::receive(link_addr src, uint8_t lane,
                                          const uint8_t* data, size_t size,
                                          time_point now, byte_buffer& out) {
  switch (inner_->receive(src, lane, data, size, now, frame_)) {
    case rx::packet:
      break;
    case rx::pending:
      return rx::pending;
    case rx::dropped:
      return rx::dropped;
  }
  switch (reassembler_.push(src, lane, frame_.data(), frame_.size(), now,
                            out)) {
    case reassembler::result::complete:
      return rx::packet;
    case reassembler::result::pending:
      return rx::pending;
    case reassembler::result::dropped:
      break;
  }
  return rx::dropped;
}

size_t fragmenting_port::expire(time_point now) {
  return reassembler_.expire(now) + inner_->expire(now);
}

std::optional<packet_port::time_point>
fragmenting_port::next_deadline() const {
  auto mine = reassembler_.next_deadline();
  auto theirs = inner_->next_deadline();
  if (mine && theirs)
    return std::min(*mine, *theirs);
  return mine ? mine : theirs;
}

void fragmenting_port::add_stats(channel_stats& st) const {
  inner_->add_stats(st);
  auto& rs = reassembler_.stats();
  st.rx_malformed += rs.malformed;
  st.rx_duplicates += rs.duplicates;
  st.rx_orphans += rs.orphans;
  st.rx_reassembly_dropped += rs.timed_out + rs.over_limit + rs.bad_checksum
                              + rs.superseded;
}

// -- factory -------------------------------------------------------------------

caf::expected<std::unique_ptr<packet_port>>
make_port(link_driver_ptr driver, reassembly_limits limits,
          frame_writer writer) {
  auto mtu = driver->profile().mtu;
  std::unique_ptr<packet_port> port
    = std::make_unique<frame_port>(driver, std::move(writer));
  if (mtu >= limits.max_packet)
    return port;
  if (mtu < min_fragment_mtu)
    return make_error(ec::invalid_parameter,
                      "an MTU of " + std::to_string(mtu)
                        + " bytes is below the smallest fragmentable MTU ("
                        + std::to_string(min_fragment_mtu) + ")");
  return std::unique_ptr<packet_port>{
    std::make_unique<fragmenting_port>(std::move(port), mtu, limits)};
}

} // namespace herm
