// tessera applybench [--meshes-list 5000,10000,20000] [--shared-vertices V] [--reps R]
// Time for the sync channel to apply a scene of many meshes (apply, update/scene_update.h),
// record by record as a client uploads it: total, and per 1000 mesh records at the start and at
// the end of the upload. With per-record work independent of the scene's size the two are equal
// and the total grows linearly with the mesh count.
#include <cstdio>

#include "app/apply_bench.h"
#include "app/command.h"
#include "app/common.h"

namespace tessera::app {
namespace {

int run(const std::vector<std::string>& argv) {
  Args args(argv);
  if (args.flag("--help")) {
    std::puts("tessera applybench [--meshes-list 5000,10000,20000] [--shared-vertices V] [--reps R]\n"
              "Times apply on N meshes (each: position buffer, index buffer, mesh record; with\n"
              "--shared-vertices V all meshes instance one geometry of V vertices). Median of R runs.");
    return 0;
  }
  std::vector<double> list = parse_number_list("--meshes-list", args.str("--meshes-list", "5000,10000,20000"));
  long shared = args.integer("--shared-vertices", 0);
  long reps = args.integer("--reps", 3);
  args.finish();
  if (reps < 1 || shared < 0) throw std::invalid_argument("--reps >= 1, --shared-vertices >= 0");
  for (double n : list) {
    if (n < 1) throw std::invalid_argument("--meshes-list: counts must be >= 1");
    std::vector<double> total, first, last;
    bench::ApplyFigures f;
    for (long r = 0; r < reps; ++r) {
      f = bench::apply_meshes(size_t(n), size_t(shared));
      total.push_back(f.total_ms);
      first.push_back(f.first_ms_per_1k);
      last.push_back(f.last_ms_per_1k);
    }
    std::printf("{\"meshes\": %zu, \"records\": %zu, \"shared_vertices\": %ld, \"apply_total_ms\": %.3f, "
                "\"first_1k_mesh_records_ms\": %.3f, \"last_1k_mesh_records_ms\": %.3f, \"us_per_record\": %.3f}\n",
                f.meshes, f.records, shared, median(total), median(first), median(last),
                1000.0 * median(total) / double(f.records));
    std::fflush(stdout);
  }
  std::printf("{\"summary\": true, \"bench\": \"applybench\", \"reps\": %ld, \"shared_vertices\": %ld, \"cpu\": %s, "
              "\"threads\": 1}\n",
              reps, shared, json_str(cpu_model()).c_str());
  return 0;
}

const Command reg("applybench", "time to apply N mesh records to a scene (sync channel, per-record checks)", run);

}  // namespace
}  // namespace tessera::app
