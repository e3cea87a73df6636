// BVH motion-capture files: reader and writer.
//
// The reader accepts any channel order and count per joint, any whitespace,
// `End Site`, scientific notation; it converts the file's units to metres
// (BVH files here are in centimetres: pass unit_to_m = 0.01). Any malformed input
// throws BvhError naming the file, the line and what is wrong.
#pragma once

#include "bodyd/base/user_error.h"
#include "bodyd/motion/skeleton.h"

#include <filesystem>
#include <stdexcept>
#include <string>
#include <vector>

namespace bodyd {

class BvhError : public UserError {
 public:
  using UserError::UserError;
};

enum class Channel : int { Xposition, Yposition, Zposition, Xrotation, Yrotation, Zrotation };

struct Motion {
  Skeleton skeleton;
  // Per joint, its channels in file order (kept so the writer can reproduce the layout).
  std::vector<std::vector<Channel>> channels;
  double frame_time_s = 1.0 / 30.0;
  std::vector<Pose> frames;

  [[nodiscard]] int frame_count() const { return static_cast<int>(frames.size()); }
  [[nodiscard]] double fps() const { return 1.0 / frame_time_s; }
};

struct BvhReadOptions {
  double unit_to_m = 0.01;  // centimetres to metres
};

// Parses BVH text; `source_name` is used in error messages.
[[nodiscard]] Motion parse_bvh(std::string_view text, const std::string& source_name,
                               const BvhReadOptions& options = {});
[[nodiscard]] Motion read_bvh(const std::filesystem::path& path, const BvhReadOptions& options = {});

// Writes a BVH file in the given unit (default centimetres) with each joint's channel layout.
// Joints whose channel layout has no position channels take their rest offset.
[[nodiscard]] std::string format_bvh(const Motion& motion, double m_to_unit = 100.0);
void write_bvh(const std::filesystem::path& path, const Motion& motion, double m_to_unit = 100.0);

}  // namespace bodyd
