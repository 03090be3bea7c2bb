// The command-line readers shared by the tessera subcommands reject bad input with a message
// that names the option, instead of rendering with a silently wrong value.
#include <catch2/catch.hpp>

#include "app/args.h"
#include "app/common.h"

using tessera::app::Args;

TEST_CASE("Number lists parse and reject bad items naming the option", "[unit]") {
  using tessera::app::parse_number_list;
  CHECK(parse_number_list("--ao-list", "1,2,4") == std::vector<double>{1, 2, 4});
  CHECK(parse_number_list("--coefficients", "1,0.5") == std::vector<double>{1, 0.5});
  CHECK(parse_number_list("--x", "").empty());
  CHECK(parse_number_list("--x", "1, 2") == std::vector<double>{1, 2});  // spaces after commas are fine
  for (const char* bad : {"1,,2", "1,a", "1.5x", ",", "1 ,2"}) {
    INFO(bad);
    CHECK_THROWS_WITH(parse_number_list("--coefficients", bad), Catch::Contains("--coefficients"));
  }
}

TEST_CASE("Options with bad or missing values are rejected", "[unit]") {
  {
    Args a({"--frames", "12x"});
    CHECK_THROWS_WITH(a.integer("--frames", 1), Catch::Contains("--frames"));
  }
  {
    Args a({"--size", "640"});  // the second value of --size is missing
    CHECK(a.integer("--size", 0, 0) == 640);
    CHECK_THROWS_WITH(a.integer("--size", 0, 1), Catch::Contains("--size"));
  }
  {
    Args a({"--scene"});
    CHECK_THROWS_WITH(a.required("--scene"), Catch::Contains("--scene"));
  }
  {
    Args a({"--ao", "4", "--aoo", "8"});  // a typo must not pass silently
    CHECK(a.integer("--ao", 0) == 4);
    CHECK_THROWS_WITH(a.finish(), Catch::Contains("--aoo"));
  }
}

TEST_CASE("Render settings outside their ranges are rejected", "[unit]") {
  for (auto bad : std::vector<std::vector<std::string>>{{"--ao", "-1"}, {"--ao", "5000"}, {"--depth", "0"}, {"--depth", "65"}}) {
    Args a(bad);
    INFO(bad[0] << " " << bad[1]);
    CHECK_THROWS_AS(tessera::app::read_settings(a), std::invalid_argument);
  }
  Args ok({"--ao", "8", "--depth", "3", "--shadows", "0"});
  auto s = tessera::app::read_settings(ok);
  CHECK(s.ao_samples == 8);
  CHECK(s.max_depth == 3);
  CHECK_FALSE(s.shadows);
}

TEST_CASE("Thread limits outside 1..1024 are rejected", "[unit]") {
  for (const char* bad : {"0", "-2", "5000"}) {
    Args a({"--threads", bad});
    INFO(bad);
    CHECK_THROWS_AS(tessera::app::limit_threads(a, nullptr), std::invalid_argument);
  }
}

TEST_CASE("--frame outside the camera loop (or negative) is refused with the valid range", "[unit]") {
  tessera::app::SceneSetup with_loop;
  with_loop.loop.frames.resize(120);
  for (const char* bad : {"-1", "120", "999999"}) {
    Args a({"--frame", bad});
    INFO(bad);
    CHECK_THROWS_WITH(tessera::app::read_frame(a, with_loop), Catch::Contains("--frame") && Catch::Contains("0..119"));
  }
  for (const char* good : {"0", "119"}) {
    Args a({"--frame", good});
    CHECK(tessera::app::read_frame(a, with_loop) == std::stol(good));
  }
  tessera::app::SceneSetup no_loop;  // the frame only seeds the AO pattern
  Args neg({"--frame", "-1"});
  CHECK_THROWS_WITH(tessera::app::read_frame(neg, no_loop), Catch::Contains("0..4294967295"));
  Args seed({"--frame", "999999"});
  CHECK(tessera::app::read_frame(seed, no_loop) == 999999);
  Args none({});
  CHECK(tessera::app::read_frame(none, with_loop) == 0);
}

TEST_CASE("--ao-distance must be finite and >= 0", "[unit]") {
  for (const char* bad : {"-1", "nan", "inf"}) {
    Args a({"--ao-distance", bad});
    INFO(bad);
    CHECK_THROWS_WITH(tessera::app::read_settings(a), Catch::Contains("--ao-distance"));
  }
  Args ok({"--ao-distance", "2.5"});
  CHECK(tessera::app::read_settings(ok).ao_distance == 2.5f);
}
