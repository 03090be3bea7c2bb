#pragma once
// What the kernel knows of a TCP connection, for the link meter (net/link_meter.h). In a file
// of its own: <linux/tcp.h>, which has the whole tcp_info, clashes with <netinet/tcp.h>,
// which asio includes.
#include <cstdint>

namespace tessera {

struct TcpFigures {
  uint64_t acked = 0;    // bytes the peer has acknowledged (tcpi_bytes_acked, Linux 4.1+)
  uint32_t notsent = 0;  // bytes written and not yet sent (tcpi_notsent_bytes, Linux 4.6+)
  bool ok = false;       // false: the kernel did not say (then both are 0)
};

// TCP_INFO of the connection `fd`.
TcpFigures tcp_figures(int fd);

}  // namespace tessera
