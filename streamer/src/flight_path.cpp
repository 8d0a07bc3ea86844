// Flight paths: parsing, built-ins and interpolation. See flight_path.h.
#include <clipstream/streamer/flight_path.h>

#include <clipstream/util/output_file.h>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <numbers>
#include <sstream>

namespace clipstream {
namespace {

constexpr double kDegToRad = std::numbers::pi / 180.0;
constexpr double kMinHeight = 1.0;  // texels: the ground plane is at 0

// Cubic Hermite on [0, 1] between p0 and p1 with tangents m0, m1 (already
// scaled to the segment length).
template <class T>
T hermite(const T& p0, const T& m0, const T& p1, const T& m1, double s) {
  const double s2 = s * s, s3 = s2 * s;
  return p0 * (2 * s3 - 3 * s2 + 1) + m0 * (s3 - 2 * s2 + s) + p1 * (-2 * s3 + 3 * s2) +
         m1 * (s3 - s2);
}

// Shortest-arc unwrap: consecutive headings differ by at most 180 degrees.
std::vector<double> unwrappedHeadings(const std::vector<Keyframe>& keys) {
  std::vector<double> h(keys.size());
  for (size_t i = 0; i < keys.size(); ++i) {
    if (i == 0) {
      h[i] = keys[i].heading_deg;
      continue;
    }
    double d = std::fmod(keys[i].heading_deg - keys[i - 1].heading_deg, 360.0);
    if (d > 180.0) d -= 360.0;
    if (d < -180.0) d += 360.0;
    h[i] = h[i - 1] + d;
  }
  return h;
}

Status fail(const std::string& what) {
  return Status::error(ErrorCode::kInvalidArgument, "flight path: " + what);
}

}  // namespace

Status FlightPath::fromJson(const std::string& text, FlightPath* out) {
  // Parsed with a callback that turns each keyframe into a Keyframe as soon
  // as its object closes and drops it from the document: a path of a
  // million keyframes holds its Keyframes, not a million JSON objects
  // (which took 14 times the file's size).
  FlightPath path;
  std::string error;  // the first problem; parsing stops there
  bool root_is_array = false;
  std::string top_key;  // the root object's key being read
  bool has_keyframes = false;
  auto isKeyframe = [&](int depth) {
    return root_is_array ? depth == 1 : depth == 2 && top_key == "keyframes";
  };
  auto keyframe = [&](const nlohmann::json& k) {
    const size_t i = path.keyframes.size();
    if (!k.is_object()) return error = "keyframe " + std::to_string(i) + " is not an object", false;
    Keyframe kf;
    double* fields[] = {&kf.t_s, &kf.position.x, &kf.position.y, &kf.position.z,
                        &kf.heading_deg, &kf.pitch_deg};
    const char* names[] = {"t", "x", "y", "z", "heading_deg", "pitch_deg"};
    for (int f = 0; f < 6; ++f) {
      const auto it = k.find(names[f]);
      if (it == k.end() || !it->is_number())
        return error = "keyframe " + std::to_string(i) + ": \"" + names[f] + "\" missing or not a number", false;
      *fields[f] = it->get<double>();
      if (!std::isfinite(*fields[f]))
        return error = "keyframe " + std::to_string(i) + ": \"" + names[f] + "\" is not finite", false;
    }
    if (kf.t_s < 0.0) return error = "keyframe " + std::to_string(i) + ": negative time", false;
    if (!path.keyframes.empty() && kf.t_s <= path.keyframes.back().t_s)
      return error = "keyframe " + std::to_string(i) + ": times must increase", false;
    path.keyframes.push_back(kf);
    return true;
  };
  using Event = nlohmann::json::parse_event_t;
  const nlohmann::json::parser_callback_t callback = [&](int depth, Event event, nlohmann::json& parsed) {
    if (!error.empty()) return false;
    if (depth == 0 && event == Event::array_start) root_is_array = true;
    if (depth == 1 && event == Event::key && !root_is_array) {
      top_key = parsed.get<std::string>();
      if (top_key == "keyframes") has_keyframes = true;
    }
    if (event == Event::object_end && isKeyframe(depth)) return keyframe(parsed) && false;  // kept as a Keyframe
    if (event == Event::value && isKeyframe(depth)) return keyframe(parsed) && false;  // not an object: an error
    return true;
  };
  nlohmann::json doc = nlohmann::json::parse(text, callback, /*allow_exceptions=*/false);
  if (!error.empty()) return fail(error);
  if (doc.is_discarded()) return fail("not valid JSON");
  if (doc.is_object()) {
    if (doc.contains("interpolation")) {
      if (!doc["interpolation"].is_string()) return fail("\"interpolation\" must be a string");
      const std::string mode = doc["interpolation"].get<std::string>();
      if (mode == "smooth") path.interpolation = Interpolation::kSmooth;
      else if (mode == "step") path.interpolation = Interpolation::kStep;
      else return fail("unknown interpolation \"" + mode + "\" (smooth or step)");
    }
    if (!has_keyframes) return fail("missing \"keyframes\"");
    if (!doc["keyframes"].is_array()) return fail("\"keyframes\" must be a non-empty array");
  } else if (!doc.is_array()) {
    return fail("\"keyframes\" must be a non-empty array");
  }
  if (path.keyframes.empty()) return fail("\"keyframes\" must be a non-empty array");
  *out = std::move(path);
  return okStatus();
}

Status FlightPath::load(const std::string& path, FlightPath* out) {
  // A FIFO would wait for a writer forever; a directory "opens" and reads as
  // nothing. Only regular files are read (docs/cli.md, "Inputs").
  std::error_code ec;
  if (std::filesystem::exists(path, ec) && !std::filesystem::is_regular_file(path, ec))
    return Status::error(ErrorCode::kIo, "flight path " + path + " is not a regular file");
  // A million keyframes is about 90 MB of JSON; anything far larger is not a
  // path, and reading it whole would only exhaust memory.
  constexpr uintmax_t kMaxPathFileBytes = uintmax_t(256) << 20;
  if (const uintmax_t bytes = std::filesystem::file_size(path, ec); !ec && bytes > kMaxPathFileBytes)
    return Status::error(ErrorCode::kInvalidArgument, "flight path " + path + " is " +
                                                          std::to_string(bytes >> 20) +
                                                          " MB, larger than any flight path (256 MB at most)");
  std::ifstream in(path, std::ios::binary);
  if (!in) return Status::error(ErrorCode::kNotFound, "flight path: cannot open " + path);
  std::string text;
  if (const uintmax_t bytes = std::filesystem::file_size(path, ec); !ec) text.reserve(size_t(bytes));
  text.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  if (in.bad()) return Status::error(ErrorCode::kIo, "flight path " + path + ": read failed");
  Status s = fromJson(text, out);
  if (!s) s.message = path + ": " + s.message;
  return s;
}

std::string FlightPath::toJson() const {
  nlohmann::json doc;
  doc["interpolation"] = interpolation == Interpolation::kStep ? "step" : "smooth";
  doc["keyframes"] = nlohmann::json::array();
  for (const Keyframe& k : keyframes)
    doc["keyframes"].push_back({{"t", k.t_s},
                                {"x", k.position.x},
                                {"y", k.position.y},
                                {"z", k.position.z},
                                {"heading_deg", k.heading_deg},
                                {"pitch_deg", k.pitch_deg}});
  return doc.dump(2) + "\n";
}

Status FlightPath::save(const std::string& path) const {
  OutputOptions options;
  options.existing = ExistingOutput::kReplaceRegular;
  return writeOutputFile(path, toJson(), options);
}

double FlightPath::durationS() const {
  return keyframes.empty() ? 0.0 : keyframes.back().t_s;
}

Camera FlightPath::sample(double t_s) const {
  Camera cam;
  if (keyframes.empty()) return cam;
  auto apply = [&](glm::dvec3 pos, double heading_deg, double pitch_deg) {
    cam.position = pos;
    cam.position.y = std::max(cam.position.y, kMinHeight);
    cam.heading_rad = heading_deg * kDegToRad;
    cam.pitch_rad = std::clamp(pitch_deg, -89.9, 89.9) * kDegToRad;
  };
  const size_t n = keyframes.size();
  if (n == 1 || t_s <= keyframes.front().t_s) {
    const Keyframe& k = keyframes.front();
    apply(k.position, k.heading_deg, k.pitch_deg);
    return cam;
  }
  if (t_s >= keyframes.back().t_s) {
    const Keyframe& k = keyframes.back();
    apply(k.position, k.heading_deg, k.pitch_deg);
    return cam;
  }
  size_t i = 0;
  while (i + 2 < n && keyframes[i + 1].t_s <= t_s) ++i;
  const Keyframe& k0 = keyframes[i];
  const Keyframe& k1 = keyframes[i + 1];
  if (interpolation == Interpolation::kStep) {
    apply(k0.position, k0.heading_deg, k0.pitch_deg);
    return cam;
  }
  const double dt = k1.t_s - k0.t_s;
  const double s = (t_s - k0.t_s) / dt;
  const std::vector<double> heading = unwrappedHeadings(keyframes);
  // Catmull-Rom tangents for non-uniform times: central differences over
  // the neighbouring keys (one-sided at the ends), scaled to this segment.
  auto tangent = [&](size_t j, auto value) {
    const size_t a = j == 0 ? 0 : j - 1, b = j + 1 < n ? j + 1 : n - 1;
    return (value(b) - value(a)) * (dt / (keyframes[b].t_s - keyframes[a].t_s));
  };
  auto pos = [&](size_t j) { return keyframes[j].position; };
  auto head = [&](size_t j) { return heading[j]; };
  auto pitch = [&](size_t j) { return keyframes[j].pitch_deg; };
  const glm::dvec3 p = hermite(pos(i), tangent(i, pos), pos(i + 1), tangent(i + 1, pos), s);
  const double h = hermite(head(i), tangent(i, head), head(i + 1), tangent(i + 1, head), s);
  const double pt = hermite(pitch(i), tangent(i, pitch), pitch(i + 1), tangent(i + 1, pitch), s);
  apply(p, h, pt);
  return cam;
}

std::vector<std::string> FlightPath::builtinNames() {
  return {"pass", "dive", "orbit", "teleport", "zoom", "valley"};
}

Status FlightPath::builtin(const std::string& name, const PyramidGeometry& geometry,
                           FlightPath* out, uint32_t teleport_frames) {
  const double w = double(geometry.width_px), h = double(geometry.height_px);
  const double side = std::min(w, h);
  const glm::dvec2 centre{w * 0.5, h * 0.5};
  FlightPath path;
  if (name == "pass") {
    // Low and fast: a few hundred screen heights per second on big textures.
    const double height = std::clamp(side * 0.002, 20.0, 2000.0);
    const double length = std::min(0.8 * w, 400.0 * height);
    for (int i = 0; i <= 4; ++i)
      path.keyframes.push_back({2.5 * i,
                                {centre.x - length * 0.5 + length * i / 4.0, height,
                                 centre.y + height * 3.0 * std::sin(i * 1.3)},
                                90.0,
                                -20.0});
  } else if (name == "dive") {
    // From orbit height straight into the ground, height falling geometrically.
    const double top = side * 0.5;
    for (int i = 0; i <= 10; ++i) {
      const double height = top * std::pow(5.0 / top, i / 10.0);
      path.keyframes.push_back({i * 1.0,
                                {centre.x + side * 0.02 * i / 10.0, height, centre.y},
                                10.0 * i,
                                -80.0 + 4.0 * i});
    }
  } else if (name == "orbit") {
    const double radius = side * 0.25, height = side * 0.1;
    const double pitch = -std::atan2(height, radius) / kDegToRad;
    for (int i = 0; i <= 12; ++i) {
      const double a = 2.0 * std::numbers::pi * i / 12.0;
      const glm::dvec2 p = centre + radius * glm::dvec2(std::sin(a), -std::cos(a));
      // Face the centre: heading 0 looks toward -z, 90 toward +x.
      const glm::dvec2 d = centre - p;
      const double heading = std::atan2(d.x, -d.y) / kDegToRad;
      path.keyframes.push_back({i * 20.0 / 12.0, {p.x, height, p.y}, heading, pitch});
    }
  } else if (name == "teleport") {
    path.interpolation = Interpolation::kStep;
    const double every_s = std::max<uint32_t>(teleport_frames, 1) / 60.0;
    uint64_t state = 0x9E3779B97F4A7C15ull;
    auto next = [&state]() {  // deterministic LCG in [0, 1)
      state = state * 6364136223846793005ull + 1442695040888963407ull;
      return double(state >> 11) * (1.0 / 9007199254740992.0);
    };
    for (int i = 0; i * every_s <= 10.0; ++i) {
      const double height = 30.0 + 270.0 * next();
      path.keyframes.push_back({i * every_s,
                                {w * (0.05 + 0.9 * next()), height, h * (0.05 + 0.9 * next())},
                                360.0 * next(),
                                -25.0 - 40.0 * next()});
    }
  } else if (name == "valley") {
    // Low and slow across the whole texture, winding, looking a little
    // down ahead: over terrain, a flight at a few texels above the ground
    // (heights are above the ground there) through whatever it crosses.
    const double height = std::clamp(side * 0.001, 3.0, 500.0);
    const double length = 0.8 * w;
    constexpr int kKeys = 8;
    for (int i = 0; i <= kKeys; ++i) {
      const double x = centre.x - length * 0.5 + length * i / kKeys;
      const double z = centre.y + 0.15 * h * std::sin(i * 0.9);
      const double dz = 0.15 * h * 0.9 * std::cos(i * 0.9) * kKeys / length;  // dz/dx of the line
      const double heading = std::atan2(1.0, -dz) / kDegToRad;  // along +x, turning with the line
      path.keyframes.push_back({3.0 * i, {x, height, z}, heading, -8.0});
    }
  } else if (name == "zoom") {
    const double top = std::max(w, h), low = 5.0;
    for (int i = 0; i <= 10; ++i) {
      const double f = i <= 5 ? i / 5.0 : (10 - i) / 5.0;
      path.keyframes.push_back({i * 1.0,
                                {centre.x, top * std::pow(low / top, f), centre.y},
                                0.0,
                                -89.0});
    }
  } else {
    return fail("unknown built-in path \"" + name + "\" (pass, dive, orbit, teleport, zoom, valley)");
  }
  *out = std::move(path);
  return okStatus();
}

}  // namespace clipstream
