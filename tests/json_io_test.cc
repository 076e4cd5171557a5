// The JSON files slapse reads and writes (core/common/json_io.h): layout and
// number formats of the writer, and errors that name the file and the key
// when a file is malformed or lacks a key.
#include <filesystem>
#include <fstream>
#include <unistd.h>
#include <string>

#include <gtest/gtest.h>

#include "core/common/intrinsics_io.h"
#include "core/common/json_io.h"
#include "lab/gt/ground_truth.h"

namespace slapse {
namespace {

class JsonFiles : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::temp_directory_path() /
           ("slapse_json_io_test_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    std::filesystem::remove_all(dir_);
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }
  std::string Write(const std::string& name, const std::string& text) {
    const std::string path = (dir_ / name).string();
    std::ofstream(path) << text;
    return path;
  }
  // A small valid drive directory (ground truth without video).
  void SaveSmallTruth() {
    GroundTruth gt;
    gt.intrinsics = Intrinsics::FromHorizontalFov(64, 48, 70.0);
    gt.mb_cols = 4;
    gt.mb_rows = 3;
    gt.fps = 30.0;
    GtPlane road;
    road.id = 0;
    road.kind = PlaneKind::kRoad;
    road.polygons_world = {{{0, 0, 0}, {1, 0, 0}, {1, 1, 0}}};
    gt.planes.push_back(road);
    for (int i = 0; i < 2; ++i) {
      GtFrame f;
      f.timestamp_s = i / 30.0;
      f.mb_labels.assign(12, 0);
      gt.frames.push_back(f);
    }
    ASSERT_TRUE(SaveGroundTruth(gt, dir_.string()).ok());
  }
  std::filesystem::path dir_;
};

TEST(DumpJson, KeepsTheFilesLayoutAndNumberFormats) {
  Json doc;
  doc["name"] = "a \"quoted\" name";
  doc["n"] = 3;
  doc["x"] = 0.5;
  doc["flag"] = true;
  doc["list"] = Json::array();
  doc["list"].push_back(Json{{"id", 1}, {"v", {1.0, 2.25}}});
  doc["list"].push_back(Json{{"id", 2}, {"v", Json::array()}});
  doc["empty"] = Json::array();
  const std::string text = DumpJson(doc, [](const std::string& key, size_t, double v) {
    return FormatDouble(key == "v" ? "%.3f" : "%.1f", v);
  });
  EXPECT_EQ(text,
            "{\n  \"name\": \"a \\\"quoted\\\" name\",\n  \"n\": 3,\n  \"x\": 0.5,\n"
            "  \"flag\": true,\n  \"list\": [\n    {\"id\": 1, \"v\": [1.000, 2.250]},\n"
            "    {\"id\": 2, \"v\": []}\n  ],\n  \"empty\": [\n  ]\n}\n");
  // What it writes parses back to the same values.
  EXPECT_EQ(Json::parse(text)["list"][0]["v"][1].get<double>(), 2.25);
  EXPECT_EQ(ExactNumber("k", 0, 0.1), "0.10000000000000001");
  EXPECT_EQ(DumpJsonLine(Json{{"a", {1.0, 2.0}}, {"b", "x"}},
                         [](const std::string&, size_t i, double v) {
                           return FormatDouble(i == 0 ? "%.1f" : "%.2f", v);
                         }),
            "{\"a\":[1.0,2.00],\"b\":\"x\"}");
}

TEST_F(JsonFiles, GroundTruthRoundTripsThroughJson) {
  SaveSmallTruth();
  auto gt = LoadGroundTruth(dir_.string());
  ASSERT_TRUE(gt.ok()) << gt.status().ToString();
  EXPECT_EQ(gt->intrinsics.width_px, 64);
  EXPECT_EQ(gt->fps, 30.0);
  ASSERT_EQ(gt->planes.size(), 1u);
  EXPECT_EQ(gt->planes[0].kind, PlaneKind::kRoad);
  ASSERT_EQ(gt->planes[0].polygons_world.size(), 1u);
  EXPECT_EQ(gt->planes[0].polygons_world[0][2], Eigen::Vector3d(1, 1, 0));
}

TEST_F(JsonFiles, CorruptGroundTruthNamesTheFile) {
  SaveSmallTruth();
  const std::string path = Write("planes.json", "{\"planes\": [ {\"id\": 0, ");
  auto gt = LoadGroundTruth(dir_.string());
  ASSERT_FALSE(gt.ok());
  EXPECT_EQ(gt.status().code(), StatusCode::kDataLoss);
  EXPECT_NE(gt.status().message().find(path + ": not valid JSON"), std::string::npos)
      << gt.status().message();
}

TEST_F(JsonFiles, MissingKeyInGroundTruthNamesFileAndKey) {
  SaveSmallTruth();
  const std::string path =
      Write("planes.json", "{\"planes\": [{\"id\": 0, \"kind\": \"road\", \"distance_m\": 0}]}");
  auto gt = LoadGroundTruth(dir_.string());
  ASSERT_FALSE(gt.ok());
  EXPECT_EQ(gt.status().message(), path + ": planes[0]: key 'normal_world' is missing");

  const std::string intr = Write("intrinsics.json", "{\"fx_px\": 50, \"fy_px\": \"50\"}");
  gt = LoadGroundTruth(dir_.string());
  ASSERT_FALSE(gt.ok());
  EXPECT_EQ(gt.status().message(), intr + ": key 'fy_px' is not a number");
}

TEST_F(JsonFiles, IntrinsicsFileErrorsNameFileAndKey) {
  const std::string good =
      Write("k.json", "{\"fx_px\": 500, \"fy_px\": 500, \"cx_px\": 319.5, \"cy_px\": 239.5}");
  auto k = ReadIntrinsicsJson(good);
  ASSERT_TRUE(k.ok()) << k.status().ToString();
  EXPECT_EQ(k->cx_px, 319.5);
  EXPECT_EQ(k->width_px, 0);  // optional: any stream size

  const std::string missing = Write("m.json", "{\"fx_px\": 500, \"fy_px\": 500, \"cx_px\": 1}");
  k = ReadIntrinsicsJson(missing);
  ASSERT_FALSE(k.ok());
  EXPECT_EQ(k.status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(k.status().message(), "intrinsics file '" + missing + "': key 'cy_px' is missing");

  const std::string corrupt = Write("c.json", "{\"fx_px\": 500,, }");
  k = ReadIntrinsicsJson(corrupt);
  ASSERT_FALSE(k.ok());
  EXPECT_NE(k.status().message().find(corrupt + ": not valid JSON"), std::string::npos)
      << k.status().message();

  const std::string negative =
      Write("n.json", "{\"fx_px\": -5, \"fy_px\": 500, \"cx_px\": 1, \"cy_px\": 1}");
  EXPECT_FALSE(ReadIntrinsicsJson(negative).ok());
  EXPECT_EQ(ReadIntrinsicsJson((dir_ / "none.json").string()).status().code(),
            StatusCode::kNotFound);
}

// Found by fuzz/fuzz_intrinsics: a number beyond a double made nlohmann throw
// out_of_range (not parse_error), which escaped and terminated the program.
TEST_F(JsonFiles, NumberBeyondDoubleIsAnErrorNotACrash) {
  const std::string path =
      Write("big.json", "{\"fx_px\": 8e822, \"fy_px\": 500, \"cx_px\": 1, \"cy_px\": 1}");
  auto doc = ReadJsonFile(path);
  ASSERT_FALSE(doc.ok());
  EXPECT_EQ(doc.status().code(), StatusCode::kDataLoss);
  EXPECT_NE(doc.status().message().find(path + ": not valid JSON"), std::string::npos)
      << doc.status().message();
  auto k = ReadIntrinsicsJson(path);
  ASSERT_FALSE(k.ok());
  EXPECT_EQ(k.status().code(), StatusCode::kInvalidArgument);
  EXPECT_FALSE(ParseIntrinsicsJson("{\"fx_px\": -1e400}", "mem").ok());
}

// The in-memory reader the fuzz harness uses agrees with the file reader.
TEST_F(JsonFiles, IntrinsicsFromTextMatchFile) {
  const std::string text = "{\"fx_px\": 500, \"fy_px\": 400, \"cx_px\": 319.5, \"cy_px\": 239.5, "
                           "\"width_px\": 640, \"height_px\": 480}";
  auto k = ParseIntrinsicsJson(text, "k");
  ASSERT_TRUE(k.ok()) << k.status().ToString();
  EXPECT_EQ(k->fy_px, 400);
  EXPECT_EQ(k->width_px, 640);
  auto from_file = ReadIntrinsicsJson(Write("k.json", text));
  ASSERT_TRUE(from_file.ok());
  EXPECT_EQ(from_file->cy_px, k->cy_px);
  EXPECT_EQ(ParseIntrinsicsJson("[1, 2]", "k").status().message(),
            "intrinsics: k: not a JSON object");
}

}  // namespace
}  // namespace slapse
