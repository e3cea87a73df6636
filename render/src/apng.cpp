#include "bodyd/render/apng.h"

#include "bodyd/render/comparison.h"

#include <fmt/format.h>
#include <zlib.h>

#include <algorithm>
#include <array>
#include <cstring>

namespace bodyd::render {
namespace {

constexpr std::array<std::uint8_t, 8> kPngSignature{0x89, 'P', 'N', 'G', '\r', '\n', 0x1A, '\n'};

std::uint32_t read_u32be(const std::uint8_t* p) {
  return (std::uint32_t{p[0]} << 24) | (std::uint32_t{p[1]} << 16) | (std::uint32_t{p[2]} << 8) | std::uint32_t{p[3]};
}

void put_u32be(std::vector<std::uint8_t>& out, std::uint32_t v) {
  out.push_back(static_cast<std::uint8_t>(v >> 24));
  out.push_back(static_cast<std::uint8_t>(v >> 16));
  out.push_back(static_cast<std::uint8_t>(v >> 8));
  out.push_back(static_cast<std::uint8_t>(v));
}

void put_u16be(std::vector<std::uint8_t>& out, std::uint16_t v) {
  out.push_back(static_cast<std::uint8_t>(v >> 8));
  out.push_back(static_cast<std::uint8_t>(v));
}

// length, type, data, CRC-32 over type and data (PNG specification, section 5.3).
void put_chunk(std::vector<std::uint8_t>& out, std::string_view type, std::span<const std::uint8_t> data) {
  put_u32be(out, static_cast<std::uint32_t>(data.size()));
  const size_t type_at = out.size();
  out.insert(out.end(), type.begin(), type.end());
  out.insert(out.end(), data.begin(), data.end());
  const uLong crc = crc32(0L, out.data() + type_at, static_cast<uInt>(4 + data.size()));
  put_u32be(out, static_cast<std::uint32_t>(crc));
}

}  // namespace

std::vector<PngChunk> parse_png_chunks(std::span<const std::uint8_t> png) {
  if (png.size() < kPngSignature.size() || !std::equal(kPngSignature.begin(), kPngSignature.end(), png.begin())) {
    throw RenderError("PNG", "no PNG signature at byte 0");
  }
  std::vector<PngChunk> chunks;
  size_t at = kPngSignature.size();
  while (at < png.size()) {
    if (png.size() - at < 12) throw RenderError("PNG", fmt::format("chunk at byte {} is cut short", at));
    const std::uint32_t length = read_u32be(&png[at]);
    if (length > png.size() - at - 12) {
      throw RenderError("PNG", fmt::format("chunk at byte {} claims {} bytes, past the end", at, length));
    }
    PngChunk chunk;
    chunk.type.assign(reinterpret_cast<const char*>(&png[at + 4]), 4);
    chunk.data.assign(png.begin() + static_cast<std::ptrdiff_t>(at + 8),
                      png.begin() + static_cast<std::ptrdiff_t>(at + 8 + length));
    const std::uint32_t crc = read_u32be(&png[at + 8 + length]);
    if (crc != static_cast<std::uint32_t>(crc32(0L, &png[at + 4], static_cast<uInt>(4 + length)))) {
      throw RenderError("PNG", fmt::format("chunk '{}' at byte {} has a wrong CRC", chunk.type, at));
    }
    at += 12 + length;
    chunks.push_back(std::move(chunk));
  }
  if (chunks.empty() || chunks.front().type != "IHDR") throw RenderError("PNG", "the first chunk is not IHDR");
  if (chunks.back().type != "IEND") throw RenderError("PNG", "the last chunk is not IEND");
  return chunks;
}

std::vector<std::uint8_t> assemble_apng(const std::vector<std::vector<std::uint8_t>>& pngs, std::uint16_t delay_num,
                                        std::uint16_t delay_den) {
  if (pngs.empty()) throw RenderError("APNG", "no frames");
  std::vector<std::vector<PngChunk>> frames;
  frames.reserve(pngs.size());
  for (size_t i = 0; i < pngs.size(); ++i) {
    try {
      frames.push_back(parse_png_chunks(pngs[i]));
    } catch (const RenderError& e) {
      throw RenderError(e.problem().under(fmt::format("APNG frame {}", i)));
    }
    const auto& chunks = frames.back();
    if (chunks.front().data.size() != 13) throw RenderError(fmt::format("APNG frame {}", i), "IHDR is not 13 bytes");
    if (chunks.front().data != frames.front().front().data) {
      throw RenderError(fmt::format("APNG frame {}", i), "its IHDR (size, depth, colour type) differs from frame 0's");
    }
    for (const PngChunk& c : chunks) {
      if (c.type == "PLTE") throw RenderError(fmt::format("APNG frame {}", i), "palette images are not supported");
    }
  }
  const std::vector<std::uint8_t>& ihdr = frames.front().front().data;
  std::vector<std::uint8_t> out(kPngSignature.begin(), kPngSignature.end());
  put_chunk(out, "IHDR", ihdr);
  std::vector<std::uint8_t> data;
  put_u32be(data, static_cast<std::uint32_t>(frames.size()));  // num_frames
  put_u32be(data, 0);                                          // num_plays: 0 = loop forever
  put_chunk(out, "acTL", data);
  std::uint32_t sequence = 0;
  for (size_t i = 0; i < frames.size(); ++i) {
    data.clear();
    put_u32be(data, sequence++);
    data.insert(data.end(), ihdr.begin(), ihdr.begin() + 8);  // width, height
    put_u32be(data, 0);                                        // x_offset
    put_u32be(data, 0);                                        // y_offset
    put_u16be(data, delay_num);
    put_u16be(data, delay_den);
    data.push_back(0);  // dispose_op: APNG_DISPOSE_OP_NONE
    data.push_back(0);  // blend_op: APNG_BLEND_OP_SOURCE (every frame is opaque and whole)
    put_chunk(out, "fcTL", data);
    for (const PngChunk& c : frames[i]) {
      if (c.type != "IDAT") continue;
      if (i == 0) {
        put_chunk(out, "IDAT", c.data);
      } else {
        data.clear();
        put_u32be(data, sequence++);
        data.insert(data.end(), c.data.begin(), c.data.end());
        put_chunk(out, "fdAT", data);
      }
    }
  }
  put_chunk(out, "IEND", {});
  return out;
}

}  // namespace bodyd::render
