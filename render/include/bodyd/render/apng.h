// Animated PNG (APNG) assembly from PNG images, per the APNG specification
// (https://wiki.mozilla.org/APNG_Specification): the first image's IHDR, an acTL chunk, then per
// frame an fcTL chunk and the image data (IDAT for the first frame, so plain PNG viewers show it;
// fdAT chunks, the same zlib stream prefixed with a sequence number, for the others). The images'
// compressed data is reused as is; only chunk framing and CRC-32 (zlib's crc32) are written here.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace bodyd::render {

struct PngChunk {
  std::string type;  // four ASCII letters
  std::vector<std::uint8_t> data;
};

// Splits a PNG file into its chunks, checking the signature, each chunk's length and CRC, and that
// it starts with IHDR and ends with IEND. Throws RenderError saying what is wrong and at which byte.
[[nodiscard]] std::vector<PngChunk> parse_png_chunks(std::span<const std::uint8_t> png);

// Assembles an APNG that loops forever, each frame shown delay_num/delay_den seconds. Every image
// must have the same IHDR (size, bit depth, colour type) and no palette; throws RenderError
// otherwise or for no images.
[[nodiscard]] std::vector<std::uint8_t> assemble_apng(const std::vector<std::vector<std::uint8_t>>& pngs,
                                                      std::uint16_t delay_num, std::uint16_t delay_den);

}  // namespace bodyd::render
