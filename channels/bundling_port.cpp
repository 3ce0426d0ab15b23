#include "channels/bundling_port.hpp"

namespace herm {

bundling_port::bundling_port(std::unique_ptr<packet_port> inner, uint32_t mtu)
  : port_decorator(std::move(inner)), mtu_(mtu) {
  frame_.reserve(mtu);
}

caf::expected<size_t> bundling_port::send(link_addr dst, uint8_t priority,
                                          const uint8_t* data, size_t size) {
  if (!inner_->congested() && is_small(size, mtu_)) {
    if (count_ > 0 && (dst != dst_ || priority != priority_))
      send_held();
    if (!bundle_append(frame_, mtu_, data, size)) {
      send_held();
      bundle_append(frame_, mtu_, data, size);
    }
    dst_ = dst;
    priority_ = priority;
    ++count_;
    bytes_ += size;
    return size_t{0};
  }
  send_held(); // keeps the order of packets
  return inner_->send(dst, priority, data, size);
}

void bundling_port::send_held() {
  if (count_ == 0)
    return;
  if (count_ == 1) {
    // Header byte and length field before the packet's bytes. The wrapped
    // port counts it as an ordinary packet (or its drop).
    auto* data = frame_.data() + frame_.size() - bytes_;
    (void) inner_->send(dst_, priority_, data, bytes_);
  } else if (inner_->send_frame(dst_, priority_, frame_.data(),
                                frame_.size())) {
    ++stats_.tx_bundles;
    stats_.tx_packets += count_;
    stats_.tx_bytes += bytes_;
  } else {
    stats_.tx_dropped += count_;
  }
  frame_.clear();
  count_ = 0;
  bytes_ = 0;
}

void bundling_port::flush() {
  send_held();
  inner_->flush();
}

packet_port::rx bundling_port::receive(link_addr src, uint8_t lane,
                                       const uint8_t* data, size_t size,
                                       time_point now, byte_buffer& out) {
  rx_rest_.clear();
  rx_next_ = 0;
  if (size == 0 || data[0] != bundle_header)
    return inner_->receive(src, lane, data, size, now, out);
  auto ok = bundle_decode(data, size, inner_->max_packet(),
                          [&](const uint8_t* p, size_t n) {
                            rx_rest_.emplace_back(p - data, n);
                          });
  if (!ok) {
    ++stats_.rx_bad;
    return rx::dropped;
  }
  ++stats_.rx_bundles;
  rx_frame_.assign(data, data + size);
  next_packet(out);
  return rx::packet;
}

bool bundling_port::next_packet(byte_buffer& out) {
  if (rx_next_ == rx_rest_.size())
    return false;
  auto [offset, n] = rx_rest_[rx_next_++];
  out.assign(rx_frame_.data() + offset, rx_frame_.data() + offset + n);
  return true;
}

void bundling_port::add_stats(channel_stats& st) const {
  inner_->add_stats(st);
  st.tx_bundles += stats_.tx_bundles;
  st.tx_frames += stats_.tx_bundles;
  st.tx_packets += stats_.tx_packets;
  st.tx_bytes += stats_.tx_bytes;
  st.tx_dropped += stats_.tx_dropped;
  st.rx_bundles += stats_.rx_bundles;
  st.rx_malformed += stats_.rx_bad;
}

std::unique_ptr<packet_port> with_bundling(std::unique_ptr<packet_port> inner,
                                           uint32_t mtu) {
  if (!bundling_port::applies(mtu, inner->max_packet()))
    return inner;
  return std::make_unique<bundling_port>(std::move(inner), mtu);
}

} // namespace herm
