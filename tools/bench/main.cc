// imr-bench: argv dispatch to subcommands. Later issues add pipeline, paper, ...
#include <cstdio>
#include <cstring>
#include <string>

namespace imr::bench {
int RunEngineBench(int argc, char** argv);
int RunPipelineBench(int argc, char** argv);
int RunPaperBench(int argc, char** argv);
int RunScalingBench(int argc, char** argv);
#ifdef IMR_BENCH_EVALUATE
int RunEvaluateBench(int argc, char** argv);
int RunPeersBench(int argc, char** argv);
int RunQualityBench(int argc, char** argv);
int RunSpeedBench(int argc, char** argv);
#endif
#ifdef IMR_BENCH_TEXTURE
int RunTextureBench(int argc, char** argv);
#endif
}

namespace {
void Usage() {
  std::fprintf(stderr,
               "usage: imr-bench <subcommand> [options]\n"
               "subcommands:\n"
               "  engine [--frames N] [--seed S] [--quick] [--modes a,b,...]\n"
               "         reconstruction engine on the synthetic street stream\n"
               "  pipeline [--frames N] [--width W --height H] [--cores C] [--kitti DIR]\n"
               "         the whole image pipeline (imr run) on one core: synthetic + KITTI\n"
               "  paper [--quick] [--modes ...] [--no-images] [--out DIR] ...\n"
               "         the paper's comparison: accuracy and per-move overhead per policy\n"
               "  scaling [--frames 250,500,1000,2000] [--out DIR] ...\n"
               "         keyframe time, total time and memory against sequence length\n"
               "  peers [--frames N] [--colmap PATH]\n"
               "         imr vs COLMAP's delaunay_mesher on identical input (needs\n"
               "         tools/bench/peers/build_colmap.sh)\n"
               "  quality [--inputs street,synth,kitti,stream] [--frames N] [--before IMR] ...\n"
               "         surface quality per input (completeness, precision, F, distances,\n"
               "         manifold, time, memory) beside the Piazza mesher and COLMAP\n"
               "  speed [--views-per-keyframe N] [--work DIR]\n"
               "         the engine on the street stream with every view a keyframe, one core\n"
               "         and two (issue 18's targets), with the time per phase\n"
               "  evaluate [--points N] [--triangles N] [--threads N] [--quick]\n"
               "         imr evaluate's distances: 1 M points against a 500 k-triangle mesh\n"
               "  texture [--sequence DIR --mesh FILE] [--frames N] [--repeat N] [--atlas-size PX]\n"
               "         colouring and texturing a mesh from its keyframe images: time per\n"
               "         keyframe and per atlas megapixel, atlas size, added memory\n");
}
}  // namespace

int main(int argc, char** argv) {
  if (argc < 2 || !std::strcmp(argv[1], "--help") || !std::strcmp(argv[1], "-h")) {
    Usage();
    return argc < 2 ? 2 : 0;
  }
  const std::string sub = argv[1];
  if (sub == "engine") return imr::bench::RunEngineBench(argc - 2, argv + 2);
  if (sub == "pipeline") return imr::bench::RunPipelineBench(argc - 2, argv + 2);
  if (sub == "paper") return imr::bench::RunPaperBench(argc - 2, argv + 2);
  if (sub == "scaling") return imr::bench::RunScalingBench(argc - 2, argv + 2);
#ifdef IMR_BENCH_EVALUATE
  if (sub == "evaluate") return imr::bench::RunEvaluateBench(argc - 2, argv + 2);
  if (sub == "peers") return imr::bench::RunPeersBench(argc - 2, argv + 2);
  if (sub == "quality") return imr::bench::RunQualityBench(argc - 2, argv + 2);
  if (sub == "speed") return imr::bench::RunSpeedBench(argc - 2, argv + 2);
#endif
#ifdef IMR_BENCH_TEXTURE
  if (sub == "texture") return imr::bench::RunTextureBench(argc - 2, argv + 2);
#endif
  std::fprintf(stderr, "imr-bench: unknown subcommand '%s'\n", sub.c_str());
  Usage();
  return 2;
}
