// The parts of HTTP/1.1 and the WebSocket protocol (RFC 6455) bodyd-viewer-bridge needs, as pure
// functions: parsing a request head, the opening handshake's accept key, server frames (never
// masked, RFC 6455 section 5.1) and client frames (always masked). No I/O here.
#pragma once

#include <cstdint>
#include <map>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace bodyd::viewer {

// ---- HTTP ------------------------------------------------------------------------------

// A request head larger than this is refused (431).
inline constexpr std::size_t kMaxRequestHeadBytes = 16 * 1024;

struct HttpRequest {
  std::string method;   // "GET"
  std::string target;   // "/index.html" (query string removed)
  std::string version;  // "HTTP/1.1"
  std::map<std::string, std::string> headers;  // names lower-cased, values trimmed
};

// Parses a request head (request line and header lines up to, not including, the empty line).
// Returns an empty string on success, otherwise what is wrong.
[[nodiscard]] std::string parse_http_request(std::string_view head, HttpRequest& out);

// True if a comma-separated header value contains `token` (case-insensitive), e.g.
// "keep-alive, Upgrade" contains "upgrade".
[[nodiscard]] bool header_has_token(std::string_view value, std::string_view token);

// A complete response with Content-Length and "Connection: close".
[[nodiscard]] std::string http_response(int status, std::string_view reason, std::string_view content_type,
                                        std::string_view body);

// ---- WebSocket -------------------------------------------------------------------------

// Sec-WebSocket-Accept for a client's Sec-WebSocket-Key: base64(SHA-1(key + the RFC's GUID)).
[[nodiscard]] std::string websocket_accept_key(std::string_view client_key);

// The 101 response completing the handshake of `request`, or an empty string with `error` set
// when the request is not a valid WebSocket upgrade (version 13).
[[nodiscard]] std::string websocket_handshake_response(const HttpRequest& request, std::string& error);

enum class Opcode : std::uint8_t { kContinuation = 0x0, kText = 0x1, kBinary = 0x2, kClose = 0x8, kPing = 0x9, kPong = 0xA };

// Appends one unfragmented, unmasked server frame to `out`.
void append_server_frame(Opcode opcode, std::span<const std::uint8_t> payload, std::vector<std::uint8_t>& out);
void append_server_frame(Opcode opcode, std::string_view payload, std::vector<std::uint8_t>& out);

// Client frames larger than this are refused (close code 1009); the viewer sends none.
inline constexpr std::size_t kMaxClientPayload = 64 * 1024;

struct ClientFrame {
  bool fin = true;
  Opcode opcode = Opcode::kText;
  std::vector<std::uint8_t> payload;  // unmasked
};

enum class FrameParse { kNeedMore, kFrame, kError };

// Parses the first frame of `bytes`. kFrame: `out` holds it and `consumed` its size; kNeedMore: the
// frame is incomplete; kError: `error` says why (unmasked frame, reserved bits, oversized payload,
// unknown opcode, fragmented or oversized control frame).
[[nodiscard]] FrameParse parse_client_frame(std::span<const std::uint8_t> bytes, ClientFrame& out, std::size_t& consumed,
                                            std::string& error);

}  // namespace bodyd::viewer
