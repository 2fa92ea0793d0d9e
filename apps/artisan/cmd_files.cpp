// artisan info / convert: what a file holds, and conversion between formats.
#include <filesystem>
#include <iostream>

#include <nlohmann/json.hpp>

#include "artisan/core/error.hpp"
#include "artisan/core/io/geometry_file.hpp"
#include "commands.hpp"

namespace artisan::cli {

namespace {

using nlohmann::json;

json box_json(const Eigen::AlignedBox3f& box) {
  if (box.isEmpty()) return nullptr;
  return {{"min", {box.min().x(), box.min().y(), box.min().z()}}, {"max", {box.max().x(), box.max().y(), box.max().z()}}};
}

json describe(const std::filesystem::path& path) {
  const auto format = io::detect_format(path);
  const auto geometry = io::load_geometry(path);
  json j = {{"path", path.string()}, {"format", io::to_string(format)}, {"kind", io::kind_name(geometry)},
            {"bytes", std::filesystem::file_size(path)}};
  if (const auto* image = std::get_if<RangeImage>(&geometry)) {
    j["width"] = image->width;
    j["height"] = image->height;
    j["valid_pixels"] = image->valid_count();
    j["bounds"] = box_json(image->bounds());
    j["sensor"] = {{"kind", image->sensor.kind}, {"name", image->sensor.name}, {"attributes", image->sensor.attributes}};
    json images = json::array();
    for (const auto& cam : image->images)
      images.push_back({{"name", cam.name}, {"width", cam.image.width}, {"height", cam.image.height}, {"channels", cam.image.channels}});
    j["images"] = images;
  } else if (const auto* mesh = std::get_if<TriangleMesh>(&geometry)) {
    j["vertices"] = mesh->vertices.size();
    j["faces"] = mesh->faces.size();
    j["has_normals"] = !mesh->normals.empty();
    j["has_uv"] = !mesh->uv.empty();
    j["has_colors"] = !mesh->colors.empty();
    j["resolution"] = mesh->median_edge_length();
    j["bounds"] = box_json(mesh->bounds());
  } else {
    const auto& cloud = std::get<PointCloud>(geometry);
    j["points"] = cloud.points.size();
    j["has_normals"] = !cloud.normals.empty();
    j["has_colors"] = !cloud.colors.empty();
    j["bounds"] = box_json(cloud.bounds());
  }
  return j;
}

std::string size_text(const json& box) {
  if (box.is_null()) return "empty";
  char buf[96];
  std::snprintf(buf, sizeof buf, "%.1f x %.1f x %.1f mm", (box["max"][0].get<double>() - box["min"][0].get<double>()) * 1e3,
                (box["max"][1].get<double>() - box["min"][1].get<double>()) * 1e3,
                (box["max"][2].get<double>() - box["min"][2].get<double>()) * 1e3);
  return buf;
}

void print_human(const json& j) {
  std::cout << j["path"].get<std::string>() << ": " << j["kind"].get<std::string>() << " (" << j["format"].get<std::string>()
            << ", " << j["bytes"].get<uint64_t>() << " bytes)\n";
  const auto kind = j["kind"].get<std::string>();
  if (kind == "range image") {
    const double pixels = j["width"].get<double>() * j["height"].get<double>();
    std::cout << "  " << j["width"] << " x " << j["height"] << " pixels, " << j["valid_pixels"] << " valid ("
              << static_cast<int>(100.0 * j["valid_pixels"].get<double>() / pixels + 0.5) << "%)\n";
    std::cout << "  sensor: " << (j["sensor"]["kind"].get<std::string>().empty() ? "unknown" : j["sensor"]["kind"].get<std::string>())
              << ", " << j["sensor"]["attributes"].size() << " attributes, " << j["images"].size() << " camera image(s)\n";
  } else if (kind == "mesh") {
    std::cout << "  " << j["vertices"] << " vertices, " << j["faces"] << " triangles, resolution "
              << j["resolution"].get<double>() * 1e3 << " mm" << (j["has_normals"].get<bool>() ? ", normals" : "")
              << (j["has_uv"].get<bool>() ? ", uv" : "") << (j["has_colors"].get<bool>() ? ", colours" : "") << "\n";
  } else {
    std::cout << "  " << j["points"] << " points" << (j["has_normals"].get<bool>() ? ", normals" : "")
              << (j["has_colors"].get<bool>() ? ", colours" : "") << "\n";
  }
  std::cout << "  extent: " << size_text(j["bounds"]) << "\n";
}

}  // namespace

void add_file_commands(CLI::App& app, const GlobalOptions& options, Action& action) {
  static std::vector<std::string> files;
  auto* info = app.add_subcommand("info", "Describe what geometry files hold (kind, size, bounds, valid pixels, faces)");
  info->add_option("files", files, "Files to describe (PLY, PCD, ARI, OBJ, STL, DAE, glTF/GLB, ...)")->required();
  info->callback([&options, &action] {
    action = [&options] {
      json all = json::array();
      int status = 0;
      for (const auto& f : files) {
        try {
          auto j = describe(f);
          if (!options.json) print_human(j);
          all.push_back(std::move(j));
        } catch (const Error& e) {
          std::cerr << "artisan: error: " << e.what() << "\n";
          all.push_back({{"path", f}, {"error", e.what()}});
          status = 1;
        }
      }
      if (options.json) std::cout << json{{"files", all}}.dump(2) << "\n";
      return status;
    };
  });

  static std::string in, out;
  auto* convert = app.add_subcommand("convert", "Convert between formats (the output format follows OUT's extension)");
  convert->add_option("in", in, "Input file")->required();
  convert->add_option("out", out, "Output file: .ply .pcd .ari (range images, point clouds), .ply .obj .gltf .glb (meshes)")->required();
  convert->callback([&options, &action] {
    action = [&options] {
      if (std::filesystem::weakly_canonical(in) == std::filesystem::weakly_canonical(out))
        throw Error("convert: input and output are the same file (" + in + ")");
      io::format_for_output(out);  // refuse an unknown output format before reading
      const auto geometry = io::load_geometry(in);
      io::save_geometry(geometry, out);
      if (options.json) {
        std::cout << json{{"input", in}, {"output", out}, {"kind", io::kind_name(geometry)}}.dump(2) << "\n";
      } else if (!options.quiet) {
        std::cerr << "wrote " << io::kind_name(geometry) << " " << out << "\n";
      }
      return 0;
    };
  });
}

}  // namespace artisan::cli
