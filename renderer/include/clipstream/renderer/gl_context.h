// OpenGL 4.5 core contexts: a headless one through EGL (tests, benchmarks,
// clipstream-fly); clipstream-view makes its window's context with GLFW itself.
//
// Owned by the GL thread: a context is made current on the thread that
// creates it and every GL call of the renderer happens on that thread.
#pragma once

#include <clipstream/store/types.h>

#include <memory>
#include <string>

namespace clipstream {

class HeadlessContext {
 public:
  // Creates an OpenGL 4.5 core context without any window or surface and
  // makes it current on the calling thread. Tries Mesa's surfaceless EGL
  // platform first, then every EGL device (EGL_EXT_platform_device) so a
  // machine with a GPU driver but no Mesa works too. kUnavailable with the
  // EGL error text when none gives a context (tests then skip).
  static Status create(std::unique_ptr<HeadlessContext>* out);
  ~HeadlessContext();
  HeadlessContext(const HeadlessContext&) = delete;
  HeadlessContext& operator=(const HeadlessContext&) = delete;

  // "surfaceless: llvmpipe (LLVM 15.0.6, 256 bits) / 4.5 (Core Profile) Mesa 22.3.6"
  const std::string& describe() const { return m_description; }

 private:
  HeadlessContext() = default;
  void* m_display = nullptr;  // EGLDisplay
  void* m_context = nullptr;  // EGLContext
  std::string m_description;
};

// Returns the GL_RENDERER / GL_VERSION pair of the current context.
std::string currentGlDescription();

// When the current context is Mesa's software rasterizer (llvmpipe,
// softpipe), keeps up to kSoftwareGlHeapKeepBytes of freed heap in the
// process instead of returning it to the kernel (glibc's M_TRIM_THRESHOLD,
// process-wide, set once), and serves blocks up to 32 MiB from the heap
// (M_MMAP_THRESHOLD); otherwise does nothing. llvmpipe bins each frame's
// triangles into 64 KiB blocks it frees after the frame: with glibc's
// default trim threshold the heap shrinks after every frame and the next
// frame faults every page back in: a third of a terrain frame's time at
// 1280x720 (docs/terrain.md, "Frame cost"). Setting the trim threshold
// fixes the mmap threshold at its 128 KiB start, so without the second
// setting every larger per-frame buffer was mapped and faulted in afresh
// (docs/decisions.md D298). Flight::create calls it; a
// program drawing without a Flight may call it after making its context
// current. Returns whether it applied the setting.
bool keepHeapForSoftwareGl();

}  // namespace clipstream
