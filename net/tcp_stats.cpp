// The kernel's TCP figures (net/tcp_stats.h).
#include "net/tcp_stats.h"

#include <linux/tcp.h>
#include <netinet/in.h>
#include <sys/socket.h>

#include <cstddef>

namespace tessera {

TcpFigures tcp_figures(int fd) {
  tcp_info info{};
  socklen_t n = sizeof info;
  TcpFigures f;
  if (::getsockopt(fd, IPPROTO_TCP, TCP_INFO, &info, &n) != 0) return f;
  if (n < offsetof(tcp_info, tcpi_notsent_bytes) + sizeof info.tcpi_notsent_bytes) return f;  // an older kernel
  f.acked = info.tcpi_bytes_acked;
  f.notsent = info.tcpi_notsent_bytes;
  f.ok = true;
  return f;
}

}  // namespace tessera
