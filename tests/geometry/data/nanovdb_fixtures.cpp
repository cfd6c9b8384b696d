// Makes the NanoVDB fixtures of tests/geometry/test_volume_format.py with NanoVDB's own
// writer, and checks .nvdb files with its own reader and validator. Not built by kdsl: to
// remake the fixtures (from a checkout of AcademySoftwareFoundation/openvdb, NanoVDB 32.9):
//   g++ -std=c++17 -O1 -I<openvdb>/nanovdb nanovdb_fixtures.cpp -o nanovdb_fixtures -lz -lblosc
//   ./nanovdb_fixtures make tests/geometry/data
//   ./nanovdb_fixtures check FILE.nvdb   # validate (full checksum), print active voxels
#define NANOVDB_USE_ZIP
#define NANOVDB_USE_BLOSC
#include <nanovdb/io/IO.h>
#include <nanovdb/tools/CreateNanoGrid.h>
#include <nanovdb/tools/CreatePrimitives.h>
#include <nanovdb/tools/GridValidator.h>

#include <cstdio>
#include <string>
#include <type_traits>

using namespace nanovdb;

// One line per active voxel, leaf by leaf: "i j k value..." (what the test compares).
template <typename BuildT>
void printVoxels(const NanoGrid<BuildT>* grid, FILE* out)
{
    const auto& tree = grid->tree();
    const auto* leaf = tree.getFirstLeaf();
    for (uint32_t n = 0; n < tree.nodeCount(0); ++n) {
        for (auto it = leaf[n].beginValueOn(); it; ++it) {
            const Coord c = it.getCoord();
            fprintf(out, "%d %d %d", c[0], c[1], c[2]);
            if constexpr (std::is_same<BuildT, Vec3f>::value) {
                const Vec3f v = *it;
                fprintf(out, " %.9g %.9g %.9g\n", v[0], v[1], v[2]);
            } else {
                fprintf(out, " %.17g\n", double(*it));
            }
        }
    }
}

template <typename HandleT>
void printAll(const HandleT& handle, FILE* out)
{
    for (uint32_t i = 0; i < handle.gridCount(); ++i) {
        if (auto* g = handle.template grid<float>(i)) printVoxels(g, out);
        if (auto* g = handle.template grid<int32_t>(i)) printVoxels(g, out);
        if (auto* g = handle.template grid<Vec3f>(i)) printVoxels(g, out);
        if (auto* g = handle.template grid<ValueOnIndex>(i)) printVoxels(g, out);
    }
}

int main(int argc, char** argv)
{
    if (argc != 3) return 2;
    const std::string mode = argv[1], path = argv[2];
    if (mode == "check") {
        for (auto& handle : io::readGrids(path)) {
            for (uint32_t i = 0; i < handle.gridCount(); ++i) {
                const bool ok = tools::validateGrid(handle, i, CheckMode::Full, true);
                printf("grid %u valid %d\n", i, int(ok));
            }
            printAll(handle, stdout);
        }
        return 0;
    }
    // A small level set (ZIP and BLOSC), a file of two grids (vec3f, int32) and an
    // OnIndex grid with its values as a feature (blind data) array.
    auto ls = tools::createLevelSetSphere<float>(4.0, Vec3d(1, 2, 3), 0.5, 2.0, Vec3d(0.25, 0, 0), "sphere");
    io::writeGrid(path + "/nanovdb_sphere_zip.nvdb", ls, io::Codec::ZIP);
    io::writeGrid(path + "/nanovdb_sphere_blosc.nvdb", ls, io::Codec::BLOSC);
    tools::build::Grid<Vec3f> velocity(Vec3f(0.5f, 0.0f, -1.0f), "velocity");
    tools::build::Grid<int32_t> labels(-7, "labels");
    for (int i = -20; i < 30; i += 3) {
        for (int j = 0; j < 9; ++j) {
            velocity.setValue(Coord(i, j, 2 * i), Vec3f(float(i), float(j), 0.25f * i * j));
            labels.setValue(Coord(i * 50, -j, 1), i * 100 + j);
        }
    }
    std::vector<GridHandle<HostBuffer>> both;
    both.push_back(tools::createNanoGrid(velocity));
    both.push_back(tools::createNanoGrid(labels));
    io::writeGrids(path + "/nanovdb_two_grids.nvdb", both, io::Codec::ZIP);
    auto index = tools::createNanoGrid<NanoGrid<float>, ValueOnIndex>(*ls.grid<float>(), 1u);
    io::writeGrid(path + "/nanovdb_onindex.nvdb", index, io::Codec::ZIP);
    const char* names[] = {"sphere", "two_grids", "onindex"};
    const GridHandle<HostBuffer>* handles[] = {&ls, nullptr, &index};
    for (int n = 0; n < 3; ++n) {
        FILE* out = fopen((path + "/nanovdb_" + names[n] + ".txt").c_str(), "w");
        if (handles[n]) printAll(*handles[n], out);
        else for (auto& h : both) printAll(h, out);
        fclose(out);
    }
    return 0;
}
