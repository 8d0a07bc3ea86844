// Headless EGL context. Surfaceless Mesa first (llvmpipe in CI), then the
// EGL device platform for machines whose GPU driver is not Mesa.
#include <clipstream/renderer/gl_context.h>

#include "gl.h"

#include <EGL/egl.h>
#include <EGL/eglext.h>

#include <malloc.h>

#include <cstring>
#include <mutex>
#include <vector>

namespace clipstream {
namespace {

std::string eglErrorText(const char* what) {
  char buf[96];
  std::snprintf(buf, sizeof buf, "%s failed (EGL error 0x%04x)", what, unsigned(eglGetError()));
  return buf;
}

bool hasExtension(const char* list, const char* name) {
  if (list == nullptr) return false;
  const size_t n = std::strlen(name);
  for (const char* p = list; (p = std::strstr(p, name)) != nullptr; p += n) {
    if ((p == list || p[-1] == ' ') && (p[n] == ' ' || p[n] == '\0')) return true;
  }
  return false;
}

// Initialises `display`, creates a 4.5 core context and makes it current
// with no surface. Returns the context or EGL_NO_CONTEXT (error in *why).
EGLContext makeCoreContext(EGLDisplay display, std::string* why) {
  EGLint major = 0, minor = 0;
  if (!eglInitialize(display, &major, &minor)) {
    *why = eglErrorText("eglInitialize");
    return EGL_NO_CONTEXT;
  }
  if (!eglBindAPI(EGL_OPENGL_API)) {
    *why = eglErrorText("eglBindAPI(OpenGL)");
    eglTerminate(display);
    return EGL_NO_CONTEXT;
  }
  const EGLint config_attribs[] = {EGL_SURFACE_TYPE, EGL_PBUFFER_BIT, EGL_RENDERABLE_TYPE,
                                   EGL_OPENGL_BIT, EGL_NONE};
  EGLConfig config = nullptr;
  EGLint count = 0;
  // Surfaceless contexts need no config on Mesa; ask for one anyway and
  // fall back to EGL_NO_CONFIG_KHR when the platform offers none.
  if (!eglChooseConfig(display, config_attribs, &config, 1, &count) || count == 0) config = nullptr;
  const EGLint ctx_attribs[] = {EGL_CONTEXT_MAJOR_VERSION, 4, EGL_CONTEXT_MINOR_VERSION, 5,
                                EGL_CONTEXT_OPENGL_PROFILE_MASK,
                                EGL_CONTEXT_OPENGL_CORE_PROFILE_BIT, EGL_NONE};
  EGLContext ctx = eglCreateContext(display, config, EGL_NO_CONTEXT, ctx_attribs);
  if (ctx == EGL_NO_CONTEXT) {
    *why = eglErrorText("eglCreateContext(4.5 core)");
    eglTerminate(display);
    return EGL_NO_CONTEXT;
  }
  if (!eglMakeCurrent(display, EGL_NO_SURFACE, EGL_NO_SURFACE, ctx)) {
    *why = eglErrorText("eglMakeCurrent(surfaceless)");
    eglDestroyContext(display, ctx);
    eglTerminate(display);
    return EGL_NO_CONTEXT;
  }
  return ctx;
}

}  // namespace

namespace {
// Freed heap kept for the software rasterizer's per-frame bins: a 1280x720
// terrain frame bins a few MiB; 256 MiB covers 4K frames with room, and is
// memory the process already had.
constexpr size_t kSoftwareGlHeapKeepBytes = size_t(256) << 20;
// Blocks up to this size come from the heap, not from mmap: setting the
// trim threshold turns off glibc's sliding mmap threshold, which left it at
// 128 KiB, so every frame's larger buffers (the ground seen's points and
// corners, the depth rows read back, the selection's vectors) were mapped,
// faulted in page by page and unmapped again. 32 MiB is glibc's largest
// (docs/decisions.md D298).
constexpr size_t kSoftwareGlMmapThresholdBytes = size_t(32) << 20;
}  // namespace

bool keepHeapForSoftwareGl() {
  const char* renderer = reinterpret_cast<const char*>(glGetString(GL_RENDERER));
  const bool software =
      renderer != nullptr && (std::strstr(renderer, "llvmpipe") != nullptr || std::strstr(renderer, "softpipe") != nullptr);
  if (!software) return false;
  static std::once_flag once;
  static bool applied = false;
  std::call_once(once, [] {
    applied = mallopt(M_TRIM_THRESHOLD, int(kSoftwareGlHeapKeepBytes)) == 1 &&
              mallopt(M_MMAP_THRESHOLD, int(kSoftwareGlMmapThresholdBytes)) == 1;
  });
  return applied;
}

std::string currentGlDescription() {
  const char* renderer = reinterpret_cast<const char*>(glGetString(GL_RENDERER));
  const char* version = reinterpret_cast<const char*>(glGetString(GL_VERSION));
  return std::string(renderer ? renderer : "?") + " / " + (version ? version : "?");
}

Status HeadlessContext::create(std::unique_ptr<HeadlessContext>* out) {
  out->reset();
  std::string why;
  const char* client_ext = eglQueryString(EGL_NO_DISPLAY, EGL_EXTENSIONS);
  auto get_platform_display = reinterpret_cast<PFNEGLGETPLATFORMDISPLAYEXTPROC>(
      eglGetProcAddress("eglGetPlatformDisplayEXT"));
  if (get_platform_display == nullptr)
    return Status::error(ErrorCode::kUnavailable, "EGL has no eglGetPlatformDisplayEXT");

  auto finish = [&](EGLDisplay display, EGLContext ctx, const char* platform) {
    std::unique_ptr<HeadlessContext> c(new HeadlessContext());
    c->m_display = display;
    c->m_context = ctx;
    c->m_description = std::string(platform) + ": " + currentGlDescription();
    *out = std::move(c);
    return okStatus();
  };

  if (hasExtension(client_ext, "EGL_MESA_platform_surfaceless")) {
    EGLDisplay display =
        get_platform_display(EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY, nullptr);
    if (display != EGL_NO_DISPLAY) {
      EGLContext ctx = makeCoreContext(display, &why);
      if (ctx != EGL_NO_CONTEXT) return finish(display, ctx, "surfaceless");
    } else {
      why = eglErrorText("eglGetPlatformDisplay(surfaceless)");
    }
  } else {
    why = "EGL_MESA_platform_surfaceless not offered";
  }

  if (hasExtension(client_ext, "EGL_EXT_platform_device")) {
    auto query_devices =
        reinterpret_cast<PFNEGLQUERYDEVICESEXTPROC>(eglGetProcAddress("eglQueryDevicesEXT"));
    EGLint count = 0;
    if (query_devices != nullptr && query_devices(0, nullptr, &count) && count > 0) {
      std::vector<EGLDeviceEXT> devices(size_t(count), nullptr);
      query_devices(count, devices.data(), &count);
      for (EGLint i = 0; i < count; ++i) {
        EGLDisplay display = get_platform_display(EGL_PLATFORM_DEVICE_EXT, devices[size_t(i)], nullptr);
        if (display == EGL_NO_DISPLAY) continue;
        EGLContext ctx = makeCoreContext(display, &why);
        if (ctx != EGL_NO_CONTEXT) return finish(display, ctx, "device");
      }
    }
  }
  return Status::error(ErrorCode::kUnavailable, "no headless OpenGL 4.5 context: " + why);
}

HeadlessContext::~HeadlessContext() {
  if (m_display != nullptr) {
    eglMakeCurrent(m_display, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
    if (m_context != nullptr) eglDestroyContext(m_display, m_context);
    eglTerminate(m_display);
  }
}

}  // namespace clipstream
