// raycut::sph from the installed package: a small render encoded as PNG (libpng linked through).
#include <raycut/sph/render.hpp>

#include <cstdio>

int main() {
  raycut::sph::RenderView view;
  view.width = 32;
  view.height = 24;
  const float xyz[3] = {0.0f, 0.5f, 0.0f};
  const auto png = raycut::sph::encode_png(raycut::sph::render(xyz, nullptr, 1, 0.0f, 1.0f, view));
  std::printf("png %zu bytes\n", png.size());
  return png.size() > 8 && png[1] == 'P' && png[2] == 'N' && png[3] == 'G' ? 0 : 1;
}
