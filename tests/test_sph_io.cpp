// The solver-independent parts of the SPH module: the article's scenario exactly as docs/sph.md
// states it, the small CI scenario, ParaView output read back by a minimal parser, and PNG files
// read back by libpng.
#include <gtest/gtest.h>

#include <unistd.h>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <png.h>

#include "raycut/error.hpp"
#include "raycut/sph/render.hpp"
#include "raycut/sph/scenario.hpp"
#include "raycut/sph/vtk.hpp"

namespace raycut::sph {
namespace {

namespace fs = std::filesystem;

constexpr double article_spacing = 0.6 / 51.0;

class SphIo : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* test = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = fs::temp_directory_path() /
           ("raycut-sph-" + std::to_string(::getpid()) + "-" + test->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string path(const std::string& name) const { return (dir_ / name).string(); }

 private:
  fs::path dir_;
};

std::string read_all(const std::string& path) {
  std::ifstream file(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(file), {});
}

std::size_t particles(const SphScenario& s) {
  return s.position.size() / 3;
}

// --- scenarios ---------------------------------------------------------------------------------

TEST(SphScenario, HiprtDropParametersAreTheArticles) {
  const SphScenario s = hiprt_drop();
  const SphParameters& p = s.params;
  EXPECT_EQ(s.name, "hiprt-drop");
  EXPECT_EQ(p.rest_density, 1000.0f);
  EXPECT_FLOAT_EQ(p.particle_mass, static_cast<float>(1000.0 * 0.216 / 131072.0));
  EXPECT_FLOAT_EQ(p.smoothing_length, 0.02f);
  EXPECT_EQ(p.stiffness, 200.0f);
  EXPECT_EQ(p.viscosity, 0.4f);
  EXPECT_EQ(p.wall_stiffness, 3000.0f);
  EXPECT_EQ(p.gravity, (std::array<float, 3>{0.0f, -9.8f, 0.0f}));
  EXPECT_EQ(p.dt, 1.0f / 320.0f);
  EXPECT_EQ(s.frames, 200);
  EXPECT_EQ(s.image_frame, 165);

  // Each wall is inside at the pool's centre and zero on its own face.
  const float centre[3] = {0.0f, 0.5f, 0.0f};
  const float faces[6][3] = {{0, 0, 0},       {0, 1, 0},        {-0.5f, 0.5f, 0},
                             {0.5f, 0.5f, 0}, {0, 0.5f, -0.5f}, {0, 0.5f, 0.5f}};
  for (int w = 0; w < 6; ++w) {
    const WallPlane& wall = p.walls[w];
    const auto s_at = [&](const float* x) {
      return wall.normal[0] * x[0] + wall.normal[1] * x[1] + wall.normal[2] * x[2] + wall.d;
    };
    EXPECT_GT(s_at(centre), 0.0f) << "wall " << w;
    EXPECT_EQ(s_at(faces[w]), 0.0f) << "wall " << w;
  }
  EXPECT_NO_THROW(validate(s));
}

TEST(SphScenario, HiprtDropLattice) {
  const SphScenario s = hiprt_drop();
  ASSERT_EQ(particles(s), 131072u);
  ASSERT_EQ(s.velocity.size(), s.position.size());
  EXPECT_TRUE(std::all_of(s.velocity.begin(), s.velocity.end(), [](float v) { return v == 0.0f; }));

  const double centre[3] = {-0.18, 0.70, 0.18};
  std::set<float> distinct[3];
  for (std::size_t i = 0; i < particles(s); ++i) {
    for (int a = 0; a < 3; ++a) {
      const float x = s.position[3 * i + a];
      ASSERT_GE(x, centre[a] - 0.3 - 1e-6) << "particle " << i << " axis " << a;
      ASSERT_LT(x, centre[a] + 0.3) << "particle " << i << " axis " << a;
      distinct[a].insert(x);
    }
  }
  for (int a = 0; a < 3; ++a) {
    ASSERT_EQ(distinct[a].size(), 51u) << "axis " << a;
    // Corner start: the first point is the cube's corner, the last one spacing short of the
    // opposite corner.
    EXPECT_NEAR(*distinct[a].begin(), centre[a] - 0.3, 1e-6);
    EXPECT_NEAR(*distinct[a].rbegin(), centre[a] + 0.3 - article_spacing, 1e-6);
    float previous = *distinct[a].begin();
    for (auto it = std::next(distinct[a].begin()); it != distinct[a].end(); ++it) {
      EXPECT_NEAR(*it - previous, article_spacing, 1e-6);
      previous = *it;
    }
  }
  // x fastest, then y, then z.
  const auto step = [&](std::size_t i, int axis) {
    return s.position[3 * i + axis] - s.position[axis];
  };
  EXPECT_NEAR(step(1, 0), article_spacing, 1e-6);
  EXPECT_EQ(step(1, 1), 0.0f);
  EXPECT_NEAR(step(51, 1), article_spacing, 1e-6);
  EXPECT_EQ(step(51, 0), 0.0f);
  EXPECT_NEAR(step(51 * 51, 2), article_spacing, 1e-6);
  EXPECT_EQ(step(51 * 51, 0), 0.0f);
  EXPECT_EQ(step(51 * 51, 1), 0.0f);
  // The last z slice is the partial one: 131072 - 50 * 51^2 points.
  const float last_z = *distinct[2].rbegin();
  std::size_t in_last_slice = 0;
  for (std::size_t i = 0; i < particles(s); ++i) in_last_slice += s.position[3 * i + 2] == last_z;
  EXPECT_EQ(in_last_slice, 131072u - 50u * 51u * 51u);
}

TEST(SphScenario, SmallDropHasRestDensityMassAndTheArticleSpacing) {
  for (std::size_t n : {1u, 8u, 4000u, 4096u, 20000u}) {
    const SphScenario s = small_drop(n);
    ASSERT_EQ(particles(s), n);
    EXPECT_NO_THROW(validate(s));
    std::size_t side = 1;
    while (side * side * side < n) ++side;
    const double block = side * article_spacing;
    const double total = s.params.particle_mass * static_cast<double>(n);
    EXPECT_NEAR(total, 1000.0 * block * block * block, 1e-5 * total) << "n = " << n;
    if (n > 1) {
      EXPECT_NEAR(s.position[3] - s.position[0], article_spacing, 1e-6) << "n = " << n;
    }
    const SphScenario article = hiprt_drop();
    EXPECT_EQ(s.params.smoothing_length, article.params.smoothing_length);
    EXPECT_EQ(s.params.stiffness, article.params.stiffness);
    EXPECT_EQ(s.params.dt, article.params.dt);
  }
}

TEST(SphScenario, SmallDropOfTheArticleSizeIsTheArticlesLattice) {
  const SphScenario small = small_drop(131072);
  const SphScenario article = hiprt_drop();
  EXPECT_EQ(small.position, article.position);
  EXPECT_EQ(small.params.particle_mass, article.params.particle_mass);
}

TEST(SphScenario, BadInputsThrow) {
  EXPECT_THROW(small_drop(0), Error);
  EXPECT_THROW(small_drop(700000), Error);
  SphScenario s = small_drop(100);
  s.position[3 * 7 + 1] = -0.01f;  // below the floor
  try {
    validate(s);
    FAIL() << "a particle below the floor was accepted";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::invalid_input);
    EXPECT_NE(std::string(e.what()).find("index 7"), std::string::npos) << e.what();
  }
  s = small_drop(100);
  s.velocity[5] = std::nanf("");
  EXPECT_THROW(validate(s), Error);
  s = small_drop(100);
  s.velocity.pop_back();
  EXPECT_THROW(validate(s), Error);
  s = small_drop(100);
  s.params.smoothing_length = 0.0f;
  EXPECT_THROW(validate(s), Error);
  s = small_drop(100);
  s.image_frame = s.frames;
  EXPECT_THROW(validate(s), Error);
}

// --- VTK
// ------------------------------------------------------------------------------------------

// A minimal reader of what write_vtp writes: the XML head, then the appended arrays by offset.
struct Vtp {
  std::size_t points = 0, verts = 0;
  std::map<std::string, std::vector<char>> arrays;  // name -> raw bytes
  std::map<std::string, int> components;

  template <class T>
  std::vector<T> get(const std::string& name) const {
    const std::vector<char>& bytes = arrays.at(name);
    std::vector<T> out(bytes.size() / sizeof(T));
    std::memcpy(out.data(), bytes.data(), out.size() * sizeof(T));
    return out;
  }
};

std::string attribute(const std::string& tag, const std::string& name) {
  std::smatch m;
  if (!std::regex_search(tag, m, std::regex("\\b" + name + "=\"([^\"]*)\""))) return {};
  return m[1];
}

Vtp read_binary_vtp(const std::string& path) {
  const std::string file = read_all(path);
  const std::size_t appended = file.find("<AppendedData encoding=\"raw\">");
  EXPECT_NE(appended, std::string::npos);
  const std::size_t data = file.find('_', appended) + 1;
  const std::string head = file.substr(0, appended);
  EXPECT_NE(head.find("header_type=\"UInt64\""), std::string::npos);
  EXPECT_NE(head.find("byte_order=\"LittleEndian\""), std::string::npos);
  Vtp vtp;
  std::smatch m;
  EXPECT_TRUE(std::regex_search(head, m, std::regex("<Piece[^>]*>")));
  vtp.points = std::stoull(attribute(m[0], "NumberOfPoints"));
  vtp.verts = std::stoull(attribute(m[0], "NumberOfVerts"));
  std::uint64_t end_of_data = 0;
  const std::regex array_tag("<DataArray[^>]*/>");
  for (auto it = std::sregex_iterator(head.begin(), head.end(), array_tag);
       it != std::sregex_iterator(); ++it) {
    const std::string tag = (*it)[0];
    EXPECT_EQ(attribute(tag, "format"), "appended");
    const std::uint64_t offset = std::stoull(attribute(tag, "offset"));
    std::uint64_t bytes = 0;
    EXPECT_LE(data + offset + 8, file.size());
    std::memcpy(&bytes, file.data() + data + offset, 8);
    EXPECT_LE(data + offset + 8 + bytes, file.size());
    const std::string name = attribute(tag, "Name");
    const char* begin = file.data() + data + offset + 8;
    vtp.arrays[name] = std::vector<char>(begin, begin + bytes);
    const std::string components = attribute(tag, "NumberOfComponents");
    vtp.components[name] = components.empty() ? 1 : std::stoi(components);
    end_of_data = std::max(end_of_data, offset + 8 + bytes);
  }
  // The arrays tile the appended section exactly, and the XML closes after it.
  EXPECT_EQ(file.substr(data + end_of_data), "\n  </AppendedData>\n</VTKFile>\n");
  return vtp;
}

struct Frame {
  std::vector<float> xyz, vel, rho, p;
};

Frame sample_frame(std::size_t n) {
  Frame f;
  for (std::size_t i = 0; i < n; ++i) {
    for (int a = 0; a < 3; ++a) {
      f.xyz.push_back(0.001f * static_cast<float>(i) + 0.1f * a);
      f.vel.push_back(-0.5f * static_cast<float>(i) / 3.0f + static_cast<float>(a));
    }
    f.rho.push_back(1000.0f + static_cast<float>(i) / 7.0f);
    f.p.push_back(static_cast<float>(i) * 1e-3f / 3.0f);
  }
  return f;
}

TEST_F(SphIo, BinaryVtpRoundTrip) {
  const std::size_t n = 1234;
  const Frame f = sample_frame(n);
  const std::string file = path("frame.vtp");
  write_vtp(file, f.xyz.data(), f.vel.data(), f.rho.data(), f.p.data(), n);
  const Vtp vtp = read_binary_vtp(file);
  EXPECT_EQ(vtp.points, n);
  EXPECT_EQ(vtp.verts, n);
  EXPECT_EQ(vtp.get<float>("Points"), f.xyz);
  EXPECT_EQ(vtp.get<float>("velocity"), f.vel);
  EXPECT_EQ(vtp.get<float>("density"), f.rho);
  EXPECT_EQ(vtp.get<float>("pressure"), f.p);
  EXPECT_EQ(vtp.components.at("Points"), 3);
  EXPECT_EQ(vtp.components.at("velocity"), 3);
  EXPECT_EQ(vtp.components.at("density"), 1);
  const std::vector<std::int32_t> connectivity = vtp.get<std::int32_t>("connectivity");
  const std::vector<std::int32_t> offsets = vtp.get<std::int32_t>("offsets");
  ASSERT_EQ(connectivity.size(), n);
  ASSERT_EQ(offsets.size(), n);
  for (std::size_t i = 0; i < n; ++i) {
    EXPECT_EQ(connectivity[i], static_cast<std::int32_t>(i));
    EXPECT_EQ(offsets[i], static_cast<std::int32_t>(i + 1));
  }
}

TEST_F(SphIo, EmptyVtpIsWellFormed) {
  const std::string file = path("empty.vtp");
  write_vtp(file, nullptr, nullptr, nullptr, nullptr, 0);
  const Vtp vtp = read_binary_vtp(file);
  EXPECT_EQ(vtp.points, 0u);
  EXPECT_EQ(vtp.arrays.size(), 6u);
  for (const auto& [name, bytes] : vtp.arrays) EXPECT_TRUE(bytes.empty()) << name;
}

TEST_F(SphIo, AsciiVtpRoundTrip) {
  const std::size_t n = 50;
  const Frame f = sample_frame(n);
  const std::string file = path("frame.vtp");
  write_vtp(file, f.xyz.data(), f.vel.data(), f.rho.data(), f.p.data(), n, VtkEncoding::ascii);
  const std::string text = read_all(file);
  EXPECT_NE(text.find("NumberOfPoints=\"50\""), std::string::npos);
  EXPECT_EQ(text.find("AppendedData"), std::string::npos);
  std::smatch m;
  ASSERT_TRUE(std::regex_search(
      text, m, std::regex("Name=\"density\" format=\"ascii\">([^<]*)</DataArray>")));
  std::istringstream values(m[1].str());
  std::vector<float> density;
  for (float v; values >> v;) density.push_back(v);
  EXPECT_EQ(density, f.rho);  // shortest round-trip text reads back exactly
}

TEST_F(SphIo, PvdListsTheFramesWithTheirTimes) {
  const Frame f = sample_frame(10);
  const std::string dir = path("out/nested");
  VtkSeries series(dir, "drop");
  const double times[] = {0.0, 1.0 / 320.0, 2.0 / 320.0};
  for (double t : times)
    series.write_frame(t, f.xyz.data(), f.vel.data(), f.rho.data(), f.p.data(), 10);
  ASSERT_EQ(series.frame_paths().size(), 3u);
  const std::string pvd = read_all(series.pvd_path());
  EXPECT_NE(pvd.find("type=\"Collection\""), std::string::npos);
  const std::regex dataset("<DataSet timestep=\"([^\"]*)\"[^>]*file=\"([^\"]*)\"/>");
  std::size_t k = 0;
  for (auto it = std::sregex_iterator(pvd.begin(), pvd.end(), dataset);
       it != std::sregex_iterator(); ++it, ++k) {
    ASSERT_LT(k, 3u);
    EXPECT_EQ(std::stod((*it)[1]), times[k]);
    const fs::path frame = fs::path(dir) / (*it)[2].str();
    EXPECT_EQ(frame.filename().string(), "drop_00000" + std::to_string(k) + ".vtp");
    EXPECT_TRUE(fs::exists(frame)) << frame;
    EXPECT_EQ(read_binary_vtp(frame.string()).points, 10u);
  }
  EXPECT_EQ(k, 3u);
  EXPECT_FALSE(fs::exists(series.pvd_path() + ".tmp"));
}

TEST_F(SphIo, VtkErrorsNameThePath) {
  const std::string blocker = path("file");
  std::ofstream(blocker) << "x";
  try {
    VtkSeries series(blocker + "/sub", "drop");
    FAIL() << "a directory under a file was accepted";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::io);
    EXPECT_NE(std::string(e.what()).find(blocker), std::string::npos) << e.what();
  }
  const Frame f = sample_frame(3);
  EXPECT_THROW(write_vtp(path("missing/dir/frame.vtp"), f.xyz.data(), f.vel.data(), f.rho.data(),
                         f.p.data(), 3),
               Error);
  EXPECT_THROW(write_vtp(path("null.vtp"), f.xyz.data(), nullptr, f.rho.data(), f.p.data(), 3),
               Error);
}

// --- PNG
// ------------------------------------------------------------------------------------------

struct DecodedPng {
  std::uint32_t width = 0, height = 0;
  std::vector<std::uint8_t> rgb;
};

// Reads a PNG back with libpng (which checks the chunk CRCs and the zlib stream): it must be 8-bit
// RGB, as encode_png writes it.
DecodedPng decode_png(const std::string& path) {
  const std::string file = read_all(path);
  DecodedPng png;
  png_image image{};
  image.version = PNG_IMAGE_VERSION;
  if (!png_image_begin_read_from_memory(&image, file.data(), file.size())) {
    ADD_FAILURE() << path << ": libpng: " << image.message;
    return png;
  }
  EXPECT_EQ(image.format, PNG_FORMAT_RGB) << path << " is not 8-bit RGB";
  image.format = PNG_FORMAT_RGB;
  png.width = image.width;
  png.height = image.height;
  png.rgb.resize(PNG_IMAGE_SIZE(image));
  if (!png_image_finish_read(&image, nullptr, png.rgb.data(), 0, nullptr)) {
    ADD_FAILURE() << path << ": libpng: " << image.message;
    png.rgb.clear();
  }
  EXPECT_EQ(image.warning_or_error, 0u) << path << ": libpng: " << image.message;
  return png;
}

std::size_t pixels_not(const DecodedPng& png, std::array<std::uint8_t, 3> colour) {
  std::size_t count = 0;
  for (std::size_t i = 0; i + 2 < png.rgb.size(); i += 3) {
    count += png.rgb[i] != colour[0] || png.rgb[i + 1] != colour[1] || png.rgb[i + 2] != colour[2];
  }
  return count;
}

TEST_F(SphIo, PngOfTheArticleBlockDecodes) {
  const SphScenario s = hiprt_drop();
  const std::size_t n = particles(s);
  std::vector<float> height(n);
  for (std::size_t i = 0; i < n; ++i) height[i] = s.position[3 * i + 1];
  const RenderView view;
  const auto start = std::chrono::steady_clock::now();
  render_png(path("drop.png"), s.position.data(), height.data(), n, 0.4f, 1.0f, view);
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  RecordProperty("render_seconds", std::to_string(seconds));

  const DecodedPng png = decode_png(path("drop.png"));
  ASSERT_EQ(png.width, 960u);
  ASSERT_EQ(png.height, 720u);
  ASSERT_EQ(png.rgb.size(), 960u * 720u * 3u);
  // The particles land where the block projects: its centre pixel is covered, the image corners
  // are background.
  const float centre[3] = {-0.18f, 0.70f, 0.18f};
  RenderView probe = view;
  probe.draw_pool = false;
  probe.particle_radius = 0.05f;
  const RgbImage dot = render(centre, nullptr, 1, 0.0f, 1.0f, probe);
  std::size_t covered = 0, dot_pixels = 0;
  for (std::size_t i = 0; i + 2 < dot.rgb.size(); i += 3) {
    if (dot.rgb[i] == view.background[0] && dot.rgb[i + 1] == view.background[1] &&
        dot.rgb[i + 2] == view.background[2]) {
      continue;
    }
    ++dot_pixels;
    covered += png.rgb[i] != view.background[0] || png.rgb[i + 1] != view.background[1] ||
               png.rgb[i + 2] != view.background[2];
  }
  EXPECT_GT(dot_pixels, 100u);
  EXPECT_EQ(covered, dot_pixels);
  for (std::size_t corner : {std::size_t{0}, std::size_t{959}, std::size_t{719 * 960}}) {
    EXPECT_EQ(png.rgb[3 * corner], view.background[0]) << "pixel " << corner;
  }
  EXPECT_GT(pixels_not(png, view.background), 20000u);
}

TEST_F(SphIo, PngOfNothingIsBackgroundPlusThePool) {
  RenderView view;
  view.width = 64;
  view.height = 48;
  render_png(path("empty.png"), nullptr, nullptr, 0, 0.0f, 1.0f, view);
  DecodedPng png = decode_png(path("empty.png"));
  EXPECT_EQ(png.width, 64u);
  EXPECT_EQ(png.height, 48u);
  EXPECT_GT(pixels_not(png, view.background), 0u);  // the pool's edges
  view.draw_pool = false;
  render_png(path("blank.png"), nullptr, nullptr, 0, 0.0f, 1.0f, view);
  png = decode_png(path("blank.png"));
  EXPECT_EQ(pixels_not(png, view.background), 0u);
}

TEST_F(SphIo, PngRoundTripsNoiseRunsAndRepeats) {
  // Every literal value, runs of every length, and repeats at distances up to the 32 KiB window.
  RgbImage image;
  image.width = 300;
  image.height = 400;
  image.rgb.resize(3u * 300u * 400u);
  std::uint32_t state = 12345;
  const auto next = [&] { return state = state * 1664525u + 1013904223u; };
  std::size_t i = 0;
  while (i < image.rgb.size()) {
    const std::uint32_t choice = next();
    const std::size_t kind = choice >> 30, length = 1 + (choice >> 8) % 600;
    const std::size_t distance = 1 + (choice >> 4) % 40000;
    for (std::size_t k = 0; k < length && i < image.rgb.size(); ++k, ++i) {
      if (kind == 0) {
        image.rgb[i] = static_cast<std::uint8_t>(next() >> 24);  // noise
      } else if (kind == 1) {
        image.rgb[i] = 77;  // a run
      } else {
        image.rgb[i] = i >= distance ? image.rgb[i - distance] : static_cast<std::uint8_t>(k);
      }
    }
  }
  write_png(path("big.png"), image);
  const DecodedPng png = decode_png(path("big.png"));
  EXPECT_EQ(png.rgb, image.rgb);
}

TEST(SphRender, ViridisEndsAndBadViews) {
  EXPECT_EQ(viridis(0.0f), (std::array<std::uint8_t, 3>{68, 1, 84}));
  EXPECT_EQ(viridis(1.0f), (std::array<std::uint8_t, 3>{253, 231, 37}));
  EXPECT_EQ(viridis(-3.0f), viridis(0.0f));
  EXPECT_EQ(viridis(7.0f), viridis(1.0f));
  const float xyz[3] = {0.0f, 0.5f, 0.0f};
  RenderView view;
  view.target = view.eye;
  EXPECT_THROW(render(xyz, nullptr, 1, 0.0f, 1.0f, view), Error);
  view = RenderView{};
  view.width = 0;
  EXPECT_THROW(render(xyz, nullptr, 1, 0.0f, 1.0f, view), Error);
  view = RenderView{};
  EXPECT_THROW(render(nullptr, nullptr, 1, 0.0f, 1.0f, view), Error);
  EXPECT_THROW(write_png("/nonexistent-dir/x.png", render(xyz, nullptr, 1, 0.0f, 1.0f, view)),
               Error);
  try {
    write_png("/nonexistent-dir/x.png", render(xyz, nullptr, 1, 0.0f, 1.0f, view));
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::io);
    EXPECT_NE(std::string(e.what()).find("/nonexistent-dir/x.png"), std::string::npos) << e.what();
  }
  RgbImage wrong;
  wrong.width = 2;
  wrong.height = 2;
  wrong.rgb.resize(3);
  EXPECT_THROW(encode_png(wrong), Error);
}

}  // namespace
}  // namespace raycut::sph
