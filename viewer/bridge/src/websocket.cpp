#include "bodyd/viewer/websocket.h"

#include <fmt/format.h>
#include <openssl/evp.h>

#include <algorithm>
#include <cctype>

namespace bodyd::viewer {
namespace {

std::string lower(std::string_view s) {
  std::string out(s);
  std::transform(out.begin(), out.end(), out.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return out;
}

std::string_view trim(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t' || s.back() == '\r')) s.remove_suffix(1);
  return s;
}

// The GUID of RFC 6455 section 1.3.
constexpr std::string_view kWebSocketGuid = "258EAFA5-E914-47DA-95CA-C5AB0DC85B11";

}  // namespace

std::string parse_http_request(std::string_view head, HttpRequest& out) {
  out = {};
  if (head.size() > kMaxRequestHeadBytes) return "request head too large";
  size_t line_end = head.find('\n');
  std::string_view line = trim(head.substr(0, line_end));
  const size_t sp1 = line.find(' ');
  const size_t sp2 = sp1 == std::string_view::npos ? sp1 : line.find(' ', sp1 + 1);
  if (sp2 == std::string_view::npos || line.find(' ', sp2 + 1) != std::string_view::npos) {
    return "malformed request line";
  }
  out.method = std::string(line.substr(0, sp1));
  std::string_view target = line.substr(sp1 + 1, sp2 - sp1 - 1);
  out.version = std::string(line.substr(sp2 + 1));
  if (out.version.rfind("HTTP/1.", 0) != 0) return "not an HTTP/1.x request";
  if (target.empty() || target.front() != '/') return "request target is not an absolute path";
  target = target.substr(0, target.find_first_of("?#"));
  out.target = std::string(target);
  while (line_end != std::string_view::npos) {
    const size_t start = line_end + 1;
    line_end = head.find('\n', start);
    std::string_view h = trim(head.substr(start, line_end == std::string_view::npos ? std::string_view::npos : line_end - start));
    if (h.empty()) continue;
    const size_t colon = h.find(':');
    if (colon == std::string_view::npos || colon == 0) return fmt::format("malformed header line '{}'", h);
    std::string name = lower(trim(h.substr(0, colon)));
    std::string value(trim(h.substr(colon + 1)));
    auto [it, inserted] = out.headers.emplace(name, value);
    if (!inserted) it->second += ", " + value;  // repeated headers combine (RFC 9110 5.3)
  }
  return {};
}

bool header_has_token(std::string_view value, std::string_view token) {
  const std::string want = lower(token);
  while (!value.empty()) {
    const size_t comma = value.find(',');
    if (lower(trim(value.substr(0, comma))) == want) return true;
    if (comma == std::string_view::npos) break;
    value.remove_prefix(comma + 1);
  }
  return false;
}

std::string http_response(int status, std::string_view reason, std::string_view content_type, std::string_view body) {
  return fmt::format(
      "HTTP/1.1 {} {}\r\nContent-Type: {}\r\nContent-Length: {}\r\nCache-Control: no-cache\r\n"
      "X-Content-Type-Options: nosniff\r\nConnection: close\r\n\r\n{}",
      status, reason, content_type, body.size(), body);
}

std::string websocket_accept_key(std::string_view client_key) {
  const std::string input = std::string(client_key) + std::string(kWebSocketGuid);
  unsigned char digest[EVP_MAX_MD_SIZE];
  unsigned int digest_len = 0;
  if (EVP_Digest(input.data(), input.size(), digest, &digest_len, EVP_sha1(), nullptr) != 1 || digest_len != 20) {
    throw std::runtime_error("OpenSSL: SHA-1 failed");
  }
  unsigned char b64[4 * ((20 + 2) / 3) + 1];
  const int n = EVP_EncodeBlock(b64, digest, static_cast<int>(digest_len));
  return std::string(reinterpret_cast<const char*>(b64), static_cast<size_t>(n));
}

std::string websocket_handshake_response(const HttpRequest& request, std::string& error) {
  auto header = [&](const char* name) -> std::string {
    auto it = request.headers.find(name);
    return it == request.headers.end() ? std::string() : it->second;
  };
  if (request.method != "GET") {
    error = "WebSocket upgrade must be a GET";
  } else if (!header_has_token(header("upgrade"), "websocket")) {
    error = "missing 'Upgrade: websocket'";
  } else if (!header_has_token(header("connection"), "upgrade")) {
    error = "missing 'Connection: Upgrade'";
  } else if (header("sec-websocket-version") != "13") {
    error = "unsupported Sec-WebSocket-Version (13 is supported)";
  } else if (header("sec-websocket-key").size() != 24) {
    error = "missing or malformed Sec-WebSocket-Key";
  } else {
    error.clear();
    return "HTTP/1.1 101 Switching Protocols\r\nUpgrade: websocket\r\nConnection: Upgrade\r\nSec-WebSocket-Accept: " +
           websocket_accept_key(header("sec-websocket-key")) + "\r\n\r\n";
  }
  return {};
}

void append_server_frame(Opcode opcode, std::span<const std::uint8_t> payload, std::vector<std::uint8_t>& out) {
  out.push_back(static_cast<std::uint8_t>(0x80u | static_cast<std::uint8_t>(opcode)));  // FIN
  const std::uint64_t n = payload.size();
  if (n < 126) {
    out.push_back(static_cast<std::uint8_t>(n));
  } else if (n <= 0xFFFF) {
    out.push_back(126);
    out.push_back(static_cast<std::uint8_t>(n >> 8));
    out.push_back(static_cast<std::uint8_t>(n));
  } else {
    out.push_back(127);
    for (int shift = 56; shift >= 0; shift -= 8) out.push_back(static_cast<std::uint8_t>(n >> shift));
  }
  out.insert(out.end(), payload.begin(), payload.end());
}

void append_server_frame(Opcode opcode, std::string_view payload, std::vector<std::uint8_t>& out) {
  append_server_frame(opcode, std::span(reinterpret_cast<const std::uint8_t*>(payload.data()), payload.size()), out);
}

FrameParse parse_client_frame(std::span<const std::uint8_t> bytes, ClientFrame& out, std::size_t& consumed,
                              std::string& error) {
  if (bytes.size() < 2) return FrameParse::kNeedMore;
  const std::uint8_t b0 = bytes[0], b1 = bytes[1];
  if (b0 & 0x70) {
    error = "reserved bits set (no extension was negotiated)";
    return FrameParse::kError;
  }
  const std::uint8_t op = b0 & 0x0F;
  const bool control = op & 0x08;
  if (!(op <= 0x2 || (op >= 0x8 && op <= 0xA))) {
    error = fmt::format("unknown opcode 0x{:x}", op);
    return FrameParse::kError;
  }
  if (!(b1 & 0x80)) {
    error = "client frame is not masked (RFC 6455 5.1)";
    return FrameParse::kError;
  }
  std::uint64_t len = b1 & 0x7F;
  size_t at = 2;
  if (len == 126) {
    if (bytes.size() < 4) return FrameParse::kNeedMore;
    len = (std::uint64_t{bytes[2]} << 8) | bytes[3];
    at = 4;
  } else if (len == 127) {
    if (bytes.size() < 10) return FrameParse::kNeedMore;
    len = 0;
    for (size_t i = 0; i < 8; ++i) len = (len << 8) | bytes[2 + i];
    at = 10;
  }
  if (control && (len > 125 || !(b0 & 0x80))) {
    error = "control frame fragmented or longer than 125 bytes";
    return FrameParse::kError;
  }
  if (len > kMaxClientPayload) {
    error = fmt::format("client frame of {} bytes (at most {})", len, kMaxClientPayload);
    return FrameParse::kError;
  }
  if (bytes.size() < at + 4 + len) return FrameParse::kNeedMore;
  const std::uint8_t* mask = &bytes[at];
  at += 4;
  out.fin = (b0 & 0x80) != 0;
  out.opcode = static_cast<Opcode>(op);
  out.payload.resize(static_cast<size_t>(len));
  for (size_t i = 0; i < len; ++i) out.payload[i] = bytes[at + i] ^ mask[i % 4];
  consumed = at + static_cast<size_t>(len);
  return FrameParse::kFrame;
}

}  // namespace bodyd::viewer
