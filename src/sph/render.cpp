// Splatting, not ray casting: each particle's sphere covers a few pixels at the default view, so
// projecting it and filling its disc is O(pixels covered) and stays well under a second for the
// article's 131,072 particles. Depth is the view-space distance along the camera axis.
#include "raycut/sph/render.hpp"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <limits>
#include <numbers>

#include <png.h>

#include "raycut/error.hpp"

namespace raycut::sph {
namespace {

struct Vec3 {
  float x, y, z;
};
Vec3 operator-(Vec3 a, Vec3 b) {
  return {a.x - b.x, a.y - b.y, a.z - b.z};
}
float dot(Vec3 a, Vec3 b) {
  return a.x * b.x + a.y * b.y + a.z * b.z;
}
Vec3 cross(Vec3 a, Vec3 b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
Vec3 normalised(Vec3 a) {
  const float length = std::sqrt(dot(a, a));
  return {a.x / length, a.y / length, a.z / length};
}
Vec3 vec(const std::array<float, 3>& a) {
  return {a[0], a[1], a[2]};
}

[[noreturn]] void invalid(const std::string& what) {
  throw Error(ErrorCode::invalid_argument, "render: " + what);
}

// A right-handed pinhole camera: screen x along `right`, screen y along `up`, depth along
// `forward`.
struct Camera {
  Vec3 eye, right, up, forward;
  float focal_px;  // pixels per unit of (lateral / depth)
  float centre_x, centre_y;
  static constexpr float near_depth = 1e-3f;

  explicit Camera(const RenderView& view) {
    eye = vec(view.eye);
    const Vec3 towards = vec(view.target) - eye;
    if (!(dot(towards, towards) > 0.0f)) invalid("eye and target must differ");
    forward = normalised(towards);
    const Vec3 side = cross(forward, vec(view.up));
    if (!(dot(side, side) > 1e-12f)) invalid("up must not be parallel to the viewing direction");
    right = normalised(side);
    up = cross(right, forward);
    const float half_fov = view.vertical_fov_degrees * std::numbers::pi_v<float> / 360.0f;
    focal_px = 0.5f * static_cast<float>(view.height) / std::tan(half_fov);
    centre_x = 0.5f * static_cast<float>(view.width);
    centre_y = 0.5f * static_cast<float>(view.height);
  }

  Vec3 to_view(Vec3 p) const {
    const Vec3 d = p - eye;
    return {dot(d, right), dot(d, up), dot(d, forward)};
  }
  // Screen coordinates in pixels (y down) of a view-space point in front of the camera.
  float screen_x(Vec3 v) const { return centre_x + focal_px * v.x / v.z; }
  float screen_y(Vec3 v) const { return centre_y - focal_px * v.y / v.z; }
};

struct Canvas {
  int width, height;
  std::vector<std::uint8_t>& rgb;
  std::vector<float> depth;

  void put(int x, int y, float z, std::array<float, 3> colour) {
    const std::size_t i = static_cast<std::size_t>(y) * width + x;
    if (!(z < depth[i])) return;  // strict: the first of equal depths wins, deterministically
    depth[i] = z;
    for (int c = 0; c < 3; ++c) {
      rgb[3 * i + c] = static_cast<std::uint8_t>(std::clamp(colour[c], 0.0f, 255.0f) + 0.5f);
    }
  }
};

std::array<float, 3> particle_colour(const float* values, std::size_t i, float value_min,
                                     float value_max) {
  float t = 0.5f;
  if (values) {
    const float v = values[i];
    if (std::isnan(v)) return {128.0f, 128.0f, 128.0f};
    if (value_max > value_min) t = (v - value_min) / (value_max - value_min);
  }
  const auto c = viridis(t);
  return {float(c[0]), float(c[1]), float(c[2])};
}

void draw_particles(const Camera& camera, Canvas& canvas, const float* xyz, const float* values,
                    std::size_t n, float value_min, float value_max, float radius) {
  // Light from the upper left, slightly towards the viewer, in view space (right, up, forward).
  const Vec3 light = normalised({-0.45f, 0.7f, -0.55f});
  constexpr float ambient = 0.3f, diffuse = 0.7f;
  for (std::size_t i = 0; i < n; ++i) {
    const Vec3 v = camera.to_view({xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]});
    if (!(v.z - radius > Camera::near_depth)) continue;  // behind the camera, or NaN
    const float sx = camera.screen_x(v), sy = camera.screen_y(v);
    const float r_px = camera.focal_px * radius / v.z;
    const std::array<float, 3> base = particle_colour(values, i, value_min, value_max);
    const int x0 = std::max(0, static_cast<int>(std::floor(sx - r_px)));
    const int x1 = std::min(canvas.width - 1, static_cast<int>(std::floor(sx + r_px)));
    const int y0 = std::max(0, static_cast<int>(std::floor(sy - r_px)));
    const int y1 = std::min(canvas.height - 1, static_cast<int>(std::floor(sy + r_px)));
    if (r_px < 0.75f) {
      // Smaller than a pixel: one flat dot, so far particles do not vanish between pixel centres.
      const int px = static_cast<int>(std::floor(sx)), py = static_cast<int>(std::floor(sy));
      if (px >= 0 && px < canvas.width && py >= 0 && py < canvas.height) {
        const float shade = ambient + diffuse * std::max(0.0f, -light.z);
        canvas.put(px, py, v.z - radius, {base[0] * shade, base[1] * shade, base[2] * shade});
      }
      continue;
    }
    const float inverse_r = 1.0f / r_px;
    for (int py = y0; py <= y1; ++py) {
      const float dy = (sy - (static_cast<float>(py) + 0.5f)) * inverse_r;  // up is +
      for (int px = x0; px <= x1; ++px) {
        const float dx = (static_cast<float>(px) + 0.5f - sx) * inverse_r;
        const float rest = 1.0f - dx * dx - dy * dy;
        if (rest < 0.0f) continue;
        // The sphere's normal at this pixel faces the camera: (dx, dy, -nz) in view space.
        const float nz = std::sqrt(rest);
        const float lambert = std::max(0.0f, dx * light.x + dy * light.y - nz * light.z);
        const float shade = ambient + diffuse * lambert;
        canvas.put(px, py, v.z - radius * nz, {base[0] * shade, base[1] * shade, base[2] * shade});
      }
    }
  }
}

// A one-pixel line with depth interpolated perspective-correctly (1/z is linear on screen). The
// depth test lets water in front hide an edge; the slack of one particle radius keeps particles
// resting against a wall from hiding the wall's own edge.
void draw_edge(const Camera& camera, Canvas& canvas, Vec3 a, Vec3 b, std::array<float, 3> colour,
               float slack) {
  Vec3 va = camera.to_view(a), vb = camera.to_view(b);
  const float near = Camera::near_depth;
  if (va.z < near && vb.z < near) return;
  // Clip the part behind the near plane.
  if (va.z < near || vb.z < near) {
    const float t = (near - va.z) / (vb.z - va.z);
    const Vec3 cut = {va.x + t * (vb.x - va.x), va.y + t * (vb.y - va.y), near};
    (va.z < near ? va : vb) = cut;
  }
  const float ax = camera.screen_x(va), ay = camera.screen_y(va);
  const float bx = camera.screen_x(vb), by = camera.screen_y(vb);
  const float length = std::max(std::abs(bx - ax), std::abs(by - ay));
  // Long off-screen stretches (an eye inside the pool) are capped; the visible part is sampled.
  const int steps = static_cast<int>(std::min(std::ceil(length), 1e5f));
  for (int s = 0; s <= steps; ++s) {
    const float t = steps == 0 ? 0.0f : static_cast<float>(s) / static_cast<float>(steps);
    const int px = static_cast<int>(std::floor(ax + t * (bx - ax)));
    const int py = static_cast<int>(std::floor(ay + t * (by - ay)));
    if (px < 0 || px >= canvas.width || py < 0 || py >= canvas.height) continue;
    const float z = 1.0f / ((1.0f - t) / va.z + t / vb.z);
    const std::size_t i = static_cast<std::size_t>(py) * canvas.width + px;
    if (z - slack < canvas.depth[i]) {
      for (int c = 0; c < 3; ++c) canvas.rgb[3 * i + c] = static_cast<std::uint8_t>(colour[c]);
    }
  }
}

void draw_box(const Camera& camera, Canvas& canvas, const RenderView& view) {
  const auto& lo = view.pool_min;
  const auto& hi = view.pool_max;
  const auto corner = [&](int bits) {
    return Vec3{(bits & 1) ? hi[0] : lo[0], (bits & 2) ? hi[1] : lo[1], (bits & 4) ? hi[2] : lo[2]};
  };
  const std::array<float, 3> colour = {float(view.edge_colour[0]), float(view.edge_colour[1]),
                                       float(view.edge_colour[2])};
  // The 12 edges join corners that differ in exactly one coordinate bit.
  for (int c = 0; c < 8; ++c) {
    for (int bit = 1; bit < 8; bit <<= 1) {
      if (!(c & bit))
        draw_edge(camera, canvas, corner(c), corner(c | bit), colour, view.particle_radius);
    }
  }
}

// PNG bytes through libpng's simplified API, which keeps libpng's setjmp/longjmp error handling
// inside libpng: a failure comes back as a zero return and a message, thrown here as Error.
std::vector<std::uint8_t> encode_with_libpng(const RgbImage& image, const std::string& what) {
  const std::size_t row_bytes = 3 * static_cast<std::size_t>(image.width);
  if (image.width < 1 || image.height < 1 ||
      row_bytes > static_cast<std::size_t>(std::numeric_limits<png_int_32>::max()) ||
      image.rgb.size() != row_bytes * static_cast<std::size_t>(image.height)) {
    throw Error(ErrorCode::invalid_argument, what + ": image size does not match its pixels");
  }
  png_image png{};
  png.version = PNG_IMAGE_VERSION;
  png.width = static_cast<png_uint_32>(image.width);
  png.height = static_cast<png_uint_32>(image.height);
  png.format = PNG_FORMAT_RGB;  // 8-bit sRGB truecolour, no alpha
  // An upper bound of the encoded size (the pixels stored, plus chunk overheads); one pass.
  std::vector<std::uint8_t> bytes(PNG_IMAGE_PNG_SIZE_MAX(png));
  png_alloc_size_t size = bytes.size();
  if (!png_image_write_to_memory(&png, bytes.data(), &size, 0, image.rgb.data(),
                                 static_cast<png_int_32>(row_bytes), nullptr)) {
    const std::string message = png.message;
    png_image_free(&png);
    throw Error(ErrorCode::io, what + ": libpng: " + message);
  }
  bytes.resize(size);
  return bytes;
}

}  // namespace

std::array<std::uint8_t, 3> viridis(float t) {
  // matplotlib's viridis sampled at t = 0, 1/8, ..., 1; linear in between is within a few levels.
  static constexpr std::uint8_t table[9][3] = {{68, 1, 84},    {71, 44, 122},  {59, 81, 139},
                                               {44, 113, 142}, {33, 144, 141}, {39, 173, 129},
                                               {92, 200, 99},  {170, 220, 50}, {253, 231, 37}};
  if (!(t > 0.0f)) t = 0.0f;  // also NaN
  if (t > 1.0f) t = 1.0f;
  const float scaled = t * 8.0f;
  const int i = std::min(7, static_cast<int>(scaled));
  const float f = scaled - static_cast<float>(i);
  std::array<std::uint8_t, 3> c;
  for (int k = 0; k < 3; ++k) {
    const float value = (1.0f - f) * table[i][k] + f * table[i + 1][k];
    c[k] = static_cast<std::uint8_t>(value + 0.5f);
  }
  return c;
}

RgbImage render(const float* xyz, const float* colour_value, std::size_t n, float value_min,
                float value_max, const RenderView& view) {
  constexpr int max_side = 16384;
  if (view.width < 1 || view.height < 1 || view.width > max_side || view.height > max_side) {
    invalid("width and height must be in [1, 16384]");
  }
  if (!(view.vertical_fov_degrees > 0.0f && view.vertical_fov_degrees < 180.0f)) {
    invalid("vertical_fov_degrees must be in (0, 180)");
  }
  if (!(std::isfinite(view.particle_radius) && view.particle_radius > 0.0f)) {
    invalid("particle_radius must be finite and > 0");
  }
  if (!std::isfinite(value_min) || !std::isfinite(value_max)) {
    invalid("value_min and value_max must be finite");
  }
  if (n > 0 && !xyz) invalid("positions must be non-null");
  const Camera camera(view);

  RgbImage image;
  image.width = view.width;
  image.height = view.height;
  const std::size_t pixels = static_cast<std::size_t>(view.width) * view.height;
  image.rgb.resize(3 * pixels);
  for (std::size_t i = 0; i < pixels; ++i) {
    for (int c = 0; c < 3; ++c) image.rgb[3 * i + c] = view.background[c];
  }
  Canvas canvas{view.width, view.height, image.rgb,
                std::vector<float>(pixels, std::numeric_limits<float>::infinity())};
  draw_particles(camera, canvas, xyz, colour_value, n, value_min, value_max, view.particle_radius);
  if (view.draw_pool) draw_box(camera, canvas, view);
  return image;
}

std::vector<std::uint8_t> encode_png(const RgbImage& image) {
  return encode_with_libpng(image, "encode_png");
}

void write_png(const std::string& path, const RgbImage& image) {
  const std::vector<std::uint8_t> png = encode_with_libpng(image, path);
  std::ofstream file(path, std::ios::binary | std::ios::trunc);
  if (!file) throw Error(ErrorCode::io, path + ": cannot open for writing");
  file.write(reinterpret_cast<const char*>(png.data()), static_cast<std::streamsize>(png.size()));
  file.close();
  if (!file) throw Error(ErrorCode::io, path + ": write failed (disk full?)");
}

void render_png(const std::string& path, const float* xyz, const float* colour_value, std::size_t n,
                float value_min, float value_max, const RenderView& view) {
  write_png(path, render(xyz, colour_value, n, value_min, value_max, view));
}

}  // namespace raycut::sph
