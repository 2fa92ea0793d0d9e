#include "artisan/core/io/stanford_conf.hpp"

#include <fstream>
#include <sstream>

#include "artisan/core/error.hpp"

namespace artisan::io {

const StanfordScanPose& StanfordConf::scan(const std::string& file) const {
  for (const auto& s : scans)
    if (s.file == file) return s;
  throw Error("the .conf file has no bmesh line for \"" + file + "\"");
}

StanfordConf read_stanford_conf(const std::filesystem::path& path) {
  std::ifstream in(path);
  if (!in) throw FileError(path, "cannot open");
  StanfordConf conf;
  std::string line;
  int line_no = 0;
  while (std::getline(in, line)) {
    ++line_no;
    std::istringstream words(line);
    std::string key;
    if (!(words >> key) || key[0] == '#') continue;
    std::string file;
    if (key == "bmesh" && !(words >> file)) throw FileError(path, "line " + std::to_string(line_no) + ": bmesh without a file name");
    if (key != "bmesh" && key != "camera") throw FileError(path, "line " + std::to_string(line_no) + ": unknown keyword \"" + key + "\"");
    double v[7];
    for (double& x : v)
      if (!(words >> x)) throw FileError(path, "line " + std::to_string(line_no) + ": expected 7 numbers (tx ty tz qx qy qz qw)");
    std::string extra;
    if (words >> extra) throw FileError(path, "line " + std::to_string(line_no) + ": unexpected \"" + extra + "\"");
    Transform T;
    try {
      // p_world = R(q)^T p_scan + t: the rotation is the conjugate of the stored quaternion.
      T = transform_from_tq({v[0], v[1], v[2]}, v[3], v[4], v[5], v[6]);
    } catch (const Error& e) {
      throw FileError(path, "line " + std::to_string(line_no) + ": " + e.what());
    }
    T.linear() = T.linear().transpose().eval();
    if (key == "camera") conf.T_world_camera = T;
    else conf.scans.push_back({file, T});
  }
  if (conf.scans.empty()) throw FileError(path, "no bmesh lines");
  return conf;
}

}  // namespace artisan::io
