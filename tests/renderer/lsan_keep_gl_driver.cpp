// Under AddressSanitizer: keeps the dlopen'd GL driver mapped until the
// process ends, so that LeakSanitizer can name it.
//
// Why: Mesa unloads its driver (swrast_dri.so, which holds llvmpipe and
// links libLLVM) with dlclose() while the process exits, before the leak
// check runs (LeakSanitizer checks from libasan's own exit handler, the
// last one). The driver's few leaked allocations then show as
// "<unknown module>" or under whatever library was mapped there later, and
// no suppression can match them without also hiding our own leaks. After
// the last test, every GL driver library already loaded is re-opened with
// RTLD_NOLOAD | RTLD_NODELETE: nothing is loaded, the driver's later
// dlclose() keeps it mapped, and its frames keep their module name
// (tests/lsan.supp matches on it). Without AddressSanitizer this file does
// nothing.
#include <gtest/gtest.h>

#if defined(__SANITIZE_ADDRESS__)

#include <dlfcn.h>
#include <link.h>

#include <cstring>
#include <string>
#include <vector>

namespace clipstream {
namespace {

// Library paths that belong to the GL driver stack Mesa loads at run time.
bool isGlDriverLibrary(const char* path) {
  return std::strstr(path, "/dri/") != nullptr || std::strstr(path, "libgallium") != nullptr ||
         std::strstr(path, "libLLVM") != nullptr || std::strstr(path, "libEGL_mesa") != nullptr;
}

class KeepGlDriverMapped : public ::testing::Environment {
 public:
  void TearDown() override {
    std::vector<std::string> paths;
    dl_iterate_phdr(
        [](dl_phdr_info* info, size_t, void* out) {
          if (info->dlpi_name != nullptr && isGlDriverLibrary(info->dlpi_name))
            static_cast<std::vector<std::string>*>(out)->push_back(info->dlpi_name);
          return 0;
        },
        &paths);
    // The handles are dropped on purpose: closing them would undo nothing
    // (RTLD_NODELETE sticks) and keeping them costs nothing.
    for (const std::string& path : paths) dlopen(path.c_str(), RTLD_LAZY | RTLD_NOLOAD | RTLD_NODELETE);
  }
};

// gtest_main owns main(); a global environment is the hook after the last test.
[[maybe_unused]] ::testing::Environment* const kKeepGlDriverMapped =
    ::testing::AddGlobalTestEnvironment(new KeepGlDriverMapped);

}  // namespace
}  // namespace clipstream

#endif  // __SANITIZE_ADDRESS__
