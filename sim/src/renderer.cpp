#include "artisan/sim/renderer.hpp"

#include <cmath>
#include <cstring>
#include <optional>
#include <random>

#define GL_GLEXT_PROTOTYPES 1
#include <GL/osmesa.h>
#include <GL/gl.h>
#include <GL/glext.h>

#include "artisan/core/error.hpp"

namespace artisan::sim {

namespace {

// Grey value noise (four octaves, tileable) for surfaces without texture of their own; the
// same for every run.
std::vector<uint8_t> noise_texture(int size) {
  std::mt19937 rng(12345);
  std::vector<float> acc(static_cast<size_t>(size) * size, 0.f);
  float amp = 1.f, total = 0.f;
  for (int cells = 8; cells <= 64; cells *= 2) {
    std::vector<float> lattice(static_cast<size_t>(cells) * cells);
    for (auto& v : lattice) v = static_cast<float>(rng() >> 8) / static_cast<float>(1 << 24);
    for (int y = 0; y < size; ++y)
      for (int x = 0; x < size; ++x) {
        const float fx = static_cast<float>(x) * cells / size, fy = static_cast<float>(y) * cells / size;
        const int x0 = static_cast<int>(fx), y0 = static_cast<int>(fy);
        const float tx = fx - x0, ty = fy - y0;
        auto L = [&](int i, int j) { return lattice[static_cast<size_t>((j % cells)) * cells + (i % cells)]; };
        const float sx = tx * tx * (3 - 2 * tx), sy = ty * ty * (3 - 2 * ty);
        const float v = (L(x0, y0) * (1 - sx) + L(x0 + 1, y0) * sx) * (1 - sy) + (L(x0, y0 + 1) * (1 - sx) + L(x0 + 1, y0 + 1) * sx) * sy;
        acc[static_cast<size_t>(y) * size + x] += amp * v;
      }
    total += amp;
    amp *= 0.7f;
  }
  std::vector<uint8_t> out(acc.size() * 3);
  for (size_t i = 0; i < acc.size(); ++i) {
    const float v = std::clamp(0.25f + 0.75f * acc[i] / total, 0.f, 1.f);
    out[3 * i] = out[3 * i + 1] = out[3 * i + 2] = static_cast<uint8_t>(std::lround(v * 255));
  }
  return out;
}

// The projection described in the header, column-major for OpenGL. Window pixel (u, v) with v
// counted from the first row in memory; OSMesa's buffer is Y-up, so memory row v is image row v.
void projection(const PinholeCamera& c, double n, double f, double out[16]) {
  std::memset(out, 0, 16 * sizeof(double));
  const double W = c.width, H = c.height;
  // clip = P * p_camera, with w_clip = z.
  out[0] = 2 * c.fx / W;                  // (0,0)
  out[8] = (2 * c.cx + 1) / W - 1;        // (0,2)
  out[5] = 2 * c.fy / H;                  // (1,1)
  out[9] = (2 * c.cy + 1) / H - 1;        // (1,2)
  out[10] = (f + n) / (f - n);            // (2,2)
  out[14] = -2 * f * n / (f - n);         // (2,3)
  out[11] = 1;                            // (3,2)
}

struct GpuMesh {
  GLuint vbo_pos = 0, vbo_normal = 0, vbo_color = 0, vbo_uv = 0, ibo = 0, texture = 0;
  GLsizei index_count = 0;
};

}  // namespace

struct Renderer::Impl {
  OSMesaContext ctx = nullptr;
  std::vector<uint8_t> buffer;  // RGBA
  int buf_w = 0, buf_h = 0;
  std::vector<GpuMesh> meshes;  // one per body
  GLuint noise = 0;

  void make_current(int w, int h) {
    if (w != buf_w || h != buf_h || buffer.empty()) {
      buffer.assign(static_cast<size_t>(w) * h * 4, 0);
      buf_w = w;
      buf_h = h;
    }
    if (!OSMesaMakeCurrent(ctx, buffer.data(), GL_UNSIGNED_BYTE, w, h))
      throw Error("renderer: OSMesaMakeCurrent failed for " + std::to_string(w) + " x " + std::to_string(h));
    OSMesaPixelStore(OSMESA_Y_UP, 1);
  }
};

Renderer::Renderer(const Workcell& cell) : impl_(std::make_unique<Impl>()) {
  const int attribs[] = {OSMESA_FORMAT, OSMESA_RGBA, OSMESA_DEPTH_BITS, 24, OSMESA_STENCIL_BITS, 0,
                         OSMESA_ACCUM_BITS, 0, OSMESA_PROFILE, OSMESA_COMPAT_PROFILE,
                         OSMESA_CONTEXT_MAJOR_VERSION, 2, OSMESA_CONTEXT_MINOR_VERSION, 1, 0};
  impl_->ctx = OSMesaCreateContextAttribs(attribs, nullptr);
  if (!impl_->ctx) throw Error("renderer: cannot create an OSMesa context (is libOSMesa installed?)");
  impl_->make_current(16, 16);

  const auto tex = noise_texture(256);
  glGenTextures(1, &impl_->noise);
  glBindTexture(GL_TEXTURE_2D, impl_->noise);
  glTexParameteri(GL_TEXTURE_2D, GL_GENERATE_MIPMAP, GL_TRUE);
  glTexImage2D(GL_TEXTURE_2D, 0, GL_RGB, 256, 256, 0, GL_RGB, GL_UNSIGNED_BYTE, tex.data());
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_LINEAR_MIPMAP_LINEAR);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_S, GL_REPEAT);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_T, GL_REPEAT);

  for (const auto& b : cell.bodies) {
    const auto& m = b.mesh;
    GpuMesh g;
    glGenBuffers(1, &g.vbo_pos);
    glBindBuffer(GL_ARRAY_BUFFER, g.vbo_pos);
    glBufferData(GL_ARRAY_BUFFER, static_cast<GLsizeiptr>(m.vertices.size() * sizeof(Eigen::Vector3f)), m.vertices.data(), GL_STATIC_DRAW);
    if (m.normals.size() == m.vertices.size()) {
      glGenBuffers(1, &g.vbo_normal);
      glBindBuffer(GL_ARRAY_BUFFER, g.vbo_normal);
      glBufferData(GL_ARRAY_BUFFER, static_cast<GLsizeiptr>(m.normals.size() * sizeof(Eigen::Vector3f)), m.normals.data(), GL_STATIC_DRAW);
    }
    if (m.colors.size() == m.vertices.size() && b.material.use_vertex_colors) {
      glGenBuffers(1, &g.vbo_color);
      glBindBuffer(GL_ARRAY_BUFFER, g.vbo_color);
      glBufferData(GL_ARRAY_BUFFER, static_cast<GLsizeiptr>(m.colors.size() * 3), m.colors.data(), GL_STATIC_DRAW);
    }
    if (m.uv.size() == m.vertices.size() && !m.texture.empty()) {
      glGenBuffers(1, &g.vbo_uv);
      glBindBuffer(GL_ARRAY_BUFFER, g.vbo_uv);
      glBufferData(GL_ARRAY_BUFFER, static_cast<GLsizeiptr>(m.uv.size() * sizeof(Eigen::Vector2f)), m.uv.data(), GL_STATIC_DRAW);
      glGenTextures(1, &g.texture);
      glBindTexture(GL_TEXTURE_2D, g.texture);
      const GLenum fmt = m.texture.channels == 4 ? GL_RGBA : m.texture.channels == 3 ? GL_RGB : GL_LUMINANCE;
      glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
      glTexParameteri(GL_TEXTURE_2D, GL_GENERATE_MIPMAP, GL_TRUE);
      glTexImage2D(GL_TEXTURE_2D, 0, GL_RGBA, m.texture.width, m.texture.height, 0, fmt, GL_UNSIGNED_BYTE, m.texture.pixels.data());
      glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_LINEAR_MIPMAP_LINEAR);
      glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
    }
    glGenBuffers(1, &g.ibo);
    glBindBuffer(GL_ELEMENT_ARRAY_BUFFER, g.ibo);
    glBufferData(GL_ELEMENT_ARRAY_BUFFER, static_cast<GLsizeiptr>(m.faces.size() * sizeof(Eigen::Vector3i)), m.faces.data(), GL_STATIC_DRAW);
    g.index_count = static_cast<GLsizei>(m.faces.size() * 3);
    impl_->meshes.push_back(g);
  }
  glBindBuffer(GL_ARRAY_BUFFER, 0);
  glBindBuffer(GL_ELEMENT_ARRAY_BUFFER, 0);
}

Renderer::~Renderer() {
  if (impl_ && impl_->ctx) OSMesaDestroyContext(impl_->ctx);
}

RenderResult Renderer::render(const Workcell& cell, const PinholeCamera& camera, const Transform& T_world_camera,
                              const RenderOptions& options) {
  camera.validate();
  if (cell.bodies.size() != impl_->meshes.size())
    throw Error("renderer: the workcell has " + std::to_string(cell.bodies.size()) + " bodies, the renderer was made for " +
                std::to_string(impl_->meshes.size()));
  if (!(options.near_m > 0 && options.far_m > options.near_m))
    throw Error("renderer: near/far planes must satisfy 0 < near < far (got " + std::to_string(options.near_m) + ", " +
                std::to_string(options.far_m) + ")");
  const int W = camera.width, H = camera.height;
  impl_->make_current(W, H);
  RenderResult out;
  out.width = W;
  out.height = H;

  glViewport(0, 0, W, H);
  glDisable(GL_DITHER);
  glDisable(GL_MULTISAMPLE);
  glDisable(GL_CULL_FACE);
  // The y-down projection mirrors the window, so faces counter-clockwise seen from outside
  // arrive clockwise: call those front faces, or two-sided lighting turns their normals inward.
  glFrontFace(GL_CW);
  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_LESS);
  glDepthRange(0.0, 1.0);
  glPixelStorei(GL_PACK_ALIGNMENT, 1);
  glMatrixMode(GL_PROJECTION);
  double P[16];
  projection(camera, options.near_m, options.far_m, P);
  glLoadMatrixd(P);
  glMatrixMode(GL_MODELVIEW);
  const Eigen::Matrix4d T_camera_world = T_world_camera.inverse().matrix();

  auto draw_bodies = [&](bool shaded) {
    glEnableClientState(GL_VERTEX_ARRAY);
    for (size_t i = 0; i < cell.bodies.size(); ++i) {
      const Body& b = cell.bodies[i];
      if (options.only_instance > 0 && b.instance_id != options.only_instance) continue;
      const GpuMesh& g = impl_->meshes[i];
      const Eigen::Matrix4d MV = T_camera_world * b.T_world_body.matrix();
      glLoadMatrixd(MV.data());
      glBindBuffer(GL_ARRAY_BUFFER, g.vbo_pos);
      glVertexPointer(3, GL_FLOAT, 0, nullptr);
      if (shaded) {
        if (g.vbo_normal) {
          glEnableClientState(GL_NORMAL_ARRAY);
          glBindBuffer(GL_ARRAY_BUFFER, g.vbo_normal);
          glNormalPointer(GL_FLOAT, 0, nullptr);
        }
        glColor4f(b.material.color.x(), b.material.color.y(), b.material.color.z(), 1.f);
        if (g.vbo_color) {
          glEnableClientState(GL_COLOR_ARRAY);
          glBindBuffer(GL_ARRAY_BUFFER, g.vbo_color);
          glColorPointer(3, GL_UNSIGNED_BYTE, 0, nullptr);
        }
        const GLfloat spec[4] = {b.material.specular, b.material.specular, b.material.specular, 1.f};
        glMaterialfv(GL_FRONT_AND_BACK, GL_SPECULAR, spec);
        glMaterialf(GL_FRONT_AND_BACK, GL_SHININESS, 32.f);
        if (g.texture) {
          glEnable(GL_TEXTURE_2D);
          glBindTexture(GL_TEXTURE_2D, g.texture);
          glEnableClientState(GL_TEXTURE_COORD_ARRAY);
          glBindBuffer(GL_ARRAY_BUFFER, g.vbo_uv);
          glTexCoordPointer(2, GL_FLOAT, 0, nullptr);
        } else if (b.material.noise_texture) {
          // Object-linear texture coordinates: s, t are two fixed oblique directions in the body
          // frame, so no axis-aligned surface is left untextured.
          const float k = 1.f / b.material.texture_scale_m;
          const GLfloat s_plane[4] = {1.0f * k, 0.3f * k, 0.6f * k, 0.f};
          const GLfloat t_plane[4] = {-0.2f * k, 1.0f * k, 0.5f * k, 0.f};
          glEnable(GL_TEXTURE_2D);
          glBindTexture(GL_TEXTURE_2D, impl_->noise);
          glTexGeni(GL_S, GL_TEXTURE_GEN_MODE, GL_OBJECT_LINEAR);
          glTexGeni(GL_T, GL_TEXTURE_GEN_MODE, GL_OBJECT_LINEAR);
          glTexGenfv(GL_S, GL_OBJECT_PLANE, s_plane);
          glTexGenfv(GL_T, GL_OBJECT_PLANE, t_plane);
          glEnable(GL_TEXTURE_GEN_S);
          glEnable(GL_TEXTURE_GEN_T);
        }
      } else {
        glColor4ub(static_cast<GLubyte>(b.instance_id & 0xff), static_cast<GLubyte>((b.instance_id >> 8) & 0xff), 0, 255);
      }
      glBindBuffer(GL_ELEMENT_ARRAY_BUFFER, g.ibo);
      glDrawElements(GL_TRIANGLES, g.index_count, GL_UNSIGNED_INT, nullptr);
      glDisableClientState(GL_NORMAL_ARRAY);
      glDisableClientState(GL_COLOR_ARRAY);
      glDisableClientState(GL_TEXTURE_COORD_ARRAY);
      glDisable(GL_TEXTURE_GEN_S);
      glDisable(GL_TEXTURE_GEN_T);
      glDisable(GL_TEXTURE_2D);
    }
    glBindBuffer(GL_ARRAY_BUFFER, 0);
    glBindBuffer(GL_ELEMENT_ARRAY_BUFFER, 0);
    glDisableClientState(GL_VERTEX_ARRAY);
  };

  const bool shaded_pass = options.color || (options.depth && !options.instances);
  bool depth_from_shaded = false;
  if (shaded_pass) {
    glClearColor(options.background.x(), options.background.y(), options.background.z(), 1.f);
    glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
    glEnable(GL_LIGHTING);
    glEnable(GL_NORMALIZE);
    glShadeModel(GL_SMOOTH);
    glLightModeli(GL_LIGHT_MODEL_TWO_SIDE, GL_TRUE);
    glEnable(GL_COLOR_MATERIAL);
    glColorMaterial(GL_FRONT_AND_BACK, GL_AMBIENT_AND_DIFFUSE);
    glTexEnvi(GL_TEXTURE_ENV, GL_TEXTURE_ENV_MODE, GL_MODULATE);
    const GLfloat no_ambient[4] = {0.f, 0.f, 0.f, 1.f};
    glLightModelfv(GL_LIGHT_MODEL_AMBIENT, no_ambient);
    for (int l = 0; l < 8; ++l) glDisable(GL_LIGHT0 + l);
    if (cell.lights.empty()) {
      // A headlight at the camera.
      glLoadIdentity();
      const GLfloat pos[4] = {0, 0, 0, 1}, dif[4] = {0.85f, 0.85f, 0.85f, 1}, amb[4] = {0.15f, 0.15f, 0.15f, 1};
      glLightfv(GL_LIGHT0, GL_POSITION, pos);
      glLightfv(GL_LIGHT0, GL_DIFFUSE, dif);
      glLightfv(GL_LIGHT0, GL_SPECULAR, dif);
      glLightfv(GL_LIGHT0, GL_AMBIENT, amb);
      glEnable(GL_LIGHT0);
    } else {
      glLoadMatrixd(T_camera_world.data());
      for (size_t l = 0; l < cell.lights.size(); ++l) {
        const auto& L = cell.lights[l];
        const GLfloat pos[4] = {static_cast<GLfloat>(L.position_world.x()), static_cast<GLfloat>(L.position_world.y()),
                                static_cast<GLfloat>(L.position_world.z()), 1.f};
        const GLfloat dif[4] = {L.diffuse.x(), L.diffuse.y(), L.diffuse.z(), 1.f};
        const GLfloat amb[4] = {L.ambient.x(), L.ambient.y(), L.ambient.z(), 1.f};
        const GLenum id = GL_LIGHT0 + static_cast<GLenum>(l);
        glLightfv(id, GL_POSITION, pos);
        glLightfv(id, GL_DIFFUSE, dif);
        glLightfv(id, GL_SPECULAR, dif);
        glLightfv(id, GL_AMBIENT, amb);
        glEnable(id);
      }
    }
    draw_bodies(true);
    glDisable(GL_LIGHTING);
    glDisable(GL_COLOR_MATERIAL);
    glFinish();
    if (options.color) {
      out.color.width = W;
      out.color.height = H;
      out.color.channels = 3;
      out.color.pixels.resize(static_cast<size_t>(W) * H * 3);
      const uint8_t* src = impl_->buffer.data();
      for (size_t i = 0; i < static_cast<size_t>(W) * H; ++i) std::memcpy(&out.color.pixels[3 * i], src + 4 * i, 3);
    }
    depth_from_shaded = true;
  }

  std::vector<float> depth_window;
  if (options.depth && depth_from_shaded) {
    depth_window.resize(static_cast<size_t>(W) * H);
    glReadPixels(0, 0, W, H, GL_DEPTH_COMPONENT, GL_FLOAT, depth_window.data());
  }

  if (options.instances) {
    glClearColor(0, 0, 0, 1);
    glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
    draw_bodies(false);
    glFinish();
    out.instance_ids.resize(static_cast<size_t>(W) * H);
    const uint8_t* src = impl_->buffer.data();
    for (size_t i = 0; i < out.instance_ids.size(); ++i)
      out.instance_ids[i] = static_cast<uint16_t>(src[4 * i] | (src[4 * i + 1] << 8));
    if (options.depth && !depth_from_shaded) {
      depth_window.resize(static_cast<size_t>(W) * H);
      glReadPixels(0, 0, W, H, GL_DEPTH_COMPONENT, GL_FLOAT, depth_window.data());
    }
  }

  if (options.depth) {
    // Window depth d in [0, 1] -> z_ndc = 2d - 1 = A + B / z (A, B from the projection).
    const double n = options.near_m, f = options.far_m;
    const double A = (f + n) / (f - n), B = -2 * f * n / (f - n);
    out.depth_m.resize(depth_window.size());
    for (size_t i = 0; i < depth_window.size(); ++i) {
      const double d = depth_window[i];
      out.depth_m[i] = d >= 1.0 ? 0.f : static_cast<float>(B / ((2 * d - 1) - A));
    }
  }
  return out;
}

PinholeCamera camera_from_fov(int width, int height, double horizontal_fov_rad) {
  if (width <= 0 || height <= 0 || !(horizontal_fov_rad > 0 && horizontal_fov_rad < 3.1))
    throw Error("camera: size " + std::to_string(width) + " x " + std::to_string(height) + " and field of view " +
                std::to_string(horizontal_fov_rad) + " rad are not valid");
  PinholeCamera c;
  c.width = width;
  c.height = height;
  c.fx = c.fy = (width / 2.0) / std::tan(horizontal_fov_rad / 2);
  c.cx = (width - 1) / 2.0;
  c.cy = (height - 1) / 2.0;
  return c;
}

std::vector<Eigen::Vector3f> unproject_depth(const PinholeCamera& camera, const std::vector<float>& depth_m) {
  std::vector<Eigen::Vector3f> points(depth_m.size(), Eigen::Vector3f::Zero());
  for (int v = 0; v < camera.height; ++v)
    for (int u = 0; u < camera.width; ++u) {
      const size_t i = static_cast<size_t>(v) * camera.width + u;
      if (depth_m[i] > 0) points[i] = camera.unproject(Eigen::Vector2d(u, v), depth_m[i]).cast<float>();
    }
  return points;
}

bool sees_point(const RenderResult& render, const PinholeCamera& camera, const Eigen::Vector3d& p_camera, double tolerance_m) {
  if (!(p_camera.z() > 0)) return false;
  const double u = camera.fx * p_camera.x() / p_camera.z() + camera.cx, v = camera.fy * p_camera.y() / p_camera.z() + camera.cy;
  const int iu = static_cast<int>(std::floor(u)), iv = static_cast<int>(std::floor(v));
  std::optional<float> farthest;
  for (int dv = 0; dv <= 1; ++dv)
    for (int du = 0; du <= 1; ++du) {
      const int uu = iu + du, vv = iv + dv;
      if (uu < 0 || vv < 0 || uu >= render.width || vv >= render.height) continue;
      const float d = render.depth_m[static_cast<size_t>(vv) * render.width + uu];
      farthest = std::max(farthest.value_or(0.f), d > 0 ? d : 1e9f);
    }
  return farthest && p_camera.z() <= *farthest + tolerance_m + 0.002 * p_camera.z();
}

}  // namespace artisan::sim
