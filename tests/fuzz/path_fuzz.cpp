// libFuzzer driver for flight paths (FlightPath::fromJson, what
// `clipstream-fly --path FILE` reads): a mutated JSON text; a path that
// parses is sampled across its span and written back, and must parse again
// to as many keyframes.
// Seeds: the built-in paths and both JSON forms.
//
//   CLIPSTREAM_FUZZ_SEEDS=corpus ./path_fuzz -runs=0   # write seeds
//   ./path_fuzz -max_total_time=300 -timeout=10 corpus
#include "fuzz_util.h"

#include <clipstream/streamer/flight_path.h>

#include <cmath>
#include <string>

using namespace clipstream;

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  if (const char* dir = fuzz::seedDir()) {
    PyramidGeometry g;
    if (!makePyramidGeometry(uint64_t(1) << 20, uint64_t(1) << 19, 128, PixelFormat::kRGBA8, &g)) std::abort();
    for (const std::string& name : FlightPath::builtinNames()) {
      FlightPath p;
      if (!FlightPath::builtin(name, g, &p)) std::abort();
      fuzz::writeFile(std::string(dir) + "/" + name + ".json", p.toJson());
    }
    fuzz::writeFile(std::string(dir) + "/array.json",
                    "[{\"t\": 0, \"x\": 1, \"y\": 50, \"z\": 2, \"heading_deg\": 10, \"pitch_deg\": -20},"
                    " {\"t\": 1.5, \"x\": 9, \"y\": 70, \"z\": -4, \"heading_deg\": 350, \"pitch_deg\": -80}]");
  }
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  FlightPath path;
  if (!FlightPath::fromJson(std::string(reinterpret_cast<const char*>(data), size), &path)) return 0;
  const double span = path.durationS();
  double sum = 0.0;
  for (int i = 0; i <= 16; ++i) sum += path.sample(span * i / 16.0).position.y;
  (void)sum;
  FlightPath again;
  if (!FlightPath::fromJson(path.toJson(), &again) || again.keyframes.size() != path.keyframes.size()) std::abort();
  return 0;
}
