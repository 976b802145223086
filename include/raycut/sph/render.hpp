// A small software renderer so users can look at an SPH run without ParaView: particles as shaded,
// z-buffered spheres coloured through a viridis colormap, the pool's edges as thin lines, written
// as PNG by libpng.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace raycut::sph {

struct RenderView {
  int width = 960;
  int height = 720;
  // The HIP RT sample's framing: its camera (eye (0.5, 1, -2), 45 degrees) uses a left-handed
  // look-at, which mirrors the scene. Reflecting through the plane x = -z, which maps the pool and
  // the initial block onto themselves, gives this right-handed camera with the same picture.
  std::array<float, 3> eye{2.0f, 1.0f, -0.5f};
  std::array<float, 3> target{0.0f, 0.5f, 0.0f};
  std::array<float, 3> up{0.0f, 1.0f, 0.0f};
  float vertical_fov_degrees = 45.0f;
  // World-space sphere radius; about half the article's lattice spacing (0.6 / 51 m), so a block
  // at rest looks solid.
  float particle_radius = 0.006f;
  bool draw_pool = true;
  std::array<float, 3> pool_min{-0.5f, 0.0f, -0.5f};
  std::array<float, 3> pool_max{0.5f, 1.0f, 0.5f};
  std::array<std::uint8_t, 3> background{24, 26, 32};
  std::array<std::uint8_t, 3> edge_colour{180, 184, 192};
};

struct RgbImage {
  int width = 0;
  int height = 0;
  std::vector<std::uint8_t> rgb;  // row-major from the top-left, 3 bytes per pixel
};

// Colours particle i by viridis((colour_value[i] - value_min) / (value_max - value_min)), clamped
// to [0, 1]; colour_value may be null (one colour), value_max <= value_min maps everything to the
// middle, and NaN values are drawn grey. xyz is (n, 3) row-major. Throws raycut::Error
// (invalid_argument) for a bad view or null positions.
RgbImage render(const float* xyz, const float* colour_value, std::size_t n, float value_min,
                float value_max, const RenderView& view = {});

// PNG bytes of an RGB image (8-bit sRGB truecolour, by libpng). Throws raycut::Error:
// invalid_argument when the pixels do not match the size, io when libpng fails.
std::vector<std::uint8_t> encode_png(const RgbImage& image);

// encode_png to a file. Throws raycut::Error naming the path (io: libpng or the file failed).
void write_png(const std::string& path, const RgbImage& image);

// render then write_png.
void render_png(const std::string& path, const float* xyz, const float* colour_value, std::size_t n,
                float value_min, float value_max, const RenderView& view = {});

// The colormap: t in [0, 1] to sRGB.
std::array<std::uint8_t, 3> viridis(float t);

}  // namespace raycut::sph
