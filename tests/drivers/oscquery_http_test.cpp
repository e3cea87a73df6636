// OSCQuery's HTTP server against idle, slow and foreign clients (issue 20 items 1, 4, 7): a pile
// of connections that never finish their headers must not keep VRChat's request from being
// answered, a page's own domain resolved to us (DNS rebinding) is refused, nothing but GET/HEAD
// is served, and stopping does not wait. The client that checks the answers is curl.
#include "../../io/vrchat/oscquery.h"

#include "bodyd/test/net.h"
#include "bodyd/test/process.h"
#include "bodyd/test/wait.h"

#include <gtest/gtest.h>
#include <spdlog/spdlog.h>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <string>
#include <vector>

namespace bodyd::drivers {
namespace {

const bool kQuietLogs = (spdlog::set_level(spdlog::level::warn), true);

bool have_curl() { return std::system("curl --version > /dev/null 2>&1") == 0; }

// curl's output for `args` (a shell word list); -s, at most 10 s.
std::string curl(const std::string& args) { return test::shell("curl -s --max-time 10 " + args + " 2>&1").out; }

// The status code curl saw for `args` ("000" when it got no answer).
std::string status_of(const std::string& args) { return curl("-o /dev/null -w '%{http_code}' " + args); }

// True once the server has closed `fd` (EOF or reset), waiting at most timeout_ms.
bool closed_by_server(int fd, int timeout_ms) {
  pollfd p{fd, POLLIN, 0};
  if (::poll(&p, 1, timeout_ms) <= 0) return false;
  char c;
  return ::recv(fd, &c, 1, MSG_DONTWAIT) <= 0;
}

struct Service {
  std::unique_ptr<detail::OscQueryService> service;
  int port = 0;
  std::string url;
  Service() {
    std::string error;
    service = detail::OscQueryService::start("bodyd-http-test", "127.0.0.1", 9001, error);
    EXPECT_TRUE(service) << error;
    if (service) port = service->http_port();
    url = "http://127.0.0.1:" + std::to_string(port);
  }
};

TEST(OscQueryHttp, IdleConnectionsDoNotKeepVrchatOut) {
  if (!have_curl()) GTEST_SKIP() << "curl is not installed";
  Service s;
  ASSERT_GT(s.port, 0);
  // 40 slowloris connections: a request line and one header, never the blank line. CivetWeb's
  // two workers each held one for 2 s, so a real request waited about 40 s.
  std::vector<int> idle;
  for (int i = 0; i < 40; ++i) {
    const int fd = test::connect_loopback(s.port);
    ASSERT_GE(fd, 0);
    const std::string part = "GET / HTTP/1.1\r\nHost: 127.0.0.1\r\n";
    ASSERT_EQ(::send(fd, part.data(), part.size(), MSG_NOSIGNAL), static_cast<ssize_t>(part.size()));
    idle.push_back(fd);
  }
  // Answered while they are open (curl gives up after 10 s).
  const std::string info = curl(s.url + "/?HOST_INFO");
  EXPECT_NE(info.find("\"OSC_PORT\":9001"), std::string::npos) << info;
  // One address may hold 16: the 24 oldest were closed to make room, and the others are closed
  // when their 2 s for the headers are up.
  int closed = 0;
  for (int fd : idle) closed += closed_by_server(fd, 5000) ? 1 : 0;
  EXPECT_EQ(closed, 40);
  for (int fd : idle) ::close(fd);
  EXPECT_EQ(status_of(s.url + "/"), "200");
}

TEST(OscQueryHttp, RefusesForeignHostNamesAndServesOnlyGet) {
  if (!have_curl()) GTEST_SKIP() << "curl is not installed";
  Service s;
  ASSERT_GT(s.port, 0);
  const std::string port = std::to_string(s.port);
  // VRChat asks by IP address (what mDNS resolved); a browser may use localhost or NAME.local.
  EXPECT_EQ(status_of(s.url + "/?HOST_INFO"), "200");
  EXPECT_EQ(status_of("-H 'Host: localhost:" + port + "' " + s.url + "/"), "200");
  EXPECT_EQ(status_of("-H 'Host: my-pc.local:" + port + "' " + s.url + "/"), "200");
  EXPECT_EQ(status_of("-H 'Host: [::1]:" + port + "' " + s.url + "/"), "200");
  // A page's own name resolved to 127.0.0.1 (DNS rebinding).
  EXPECT_EQ(status_of("-H 'Host: evil.example:" + port + "' " + s.url + "/?HOST_INFO"), "403");
  EXPECT_EQ(status_of("-H 'Host: 127.0.0.1.evil.example' " + s.url + "/"), "403");
  // Read-only: nothing but GET and HEAD.
  EXPECT_EQ(status_of("-X POST -H 'Content-Type: application/json' --data '{}' " + s.url + "/tracking/vrsystem"), "405");
  EXPECT_EQ(status_of("-X PUT --data x " + s.url + "/"), "405");
  EXPECT_EQ(status_of("-X OPTIONS -H 'Origin: http://evil.example' -H 'Access-Control-Request-Method: GET' " + s.url + "/"),
            "405");
  EXPECT_EQ(status_of("-I " + s.url + "/"), "200");
  // No CORS: a page of another origin cannot read the tree.
  const std::string headers = curl("-D - -o /dev/null -H 'Origin: http://evil.example' " + s.url + "/");
  EXPECT_NE(headers.find("200 OK"), std::string::npos) << headers;
  EXPECT_EQ(headers.find("Access-Control"), std::string::npos) << headers;
  // Headers over 8 KiB.
  EXPECT_EQ(status_of("-H 'X-Big: " + std::string(9000, 'a') + "' " + s.url + "/"), "431");
}

TEST(OscQueryHttp, StopsPromptlyWithAClientConnected) {
  Service s;
  ASSERT_GT(s.port, 0);
  const int fd = test::connect_loopback(s.port);
  ASSERT_GE(fd, 0);
  // CivetWeb's accept thread polled in 2 s steps, so bodyd's shutdown took 2 s with OSCQuery on.
  // Stopping returns without the client finishing its request, and closes its connection (how
  // long stopping takes: bodyd-bench-stop).
  EXPECT_TRUE(test::returns_within([&] { s.service.reset(); }, std::chrono::milliseconds(10000)));
  EXPECT_TRUE(closed_by_server(fd, 1000));
  ::close(fd);
}

}  // namespace
}  // namespace bodyd::drivers
