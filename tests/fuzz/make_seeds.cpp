// Writes the generated seeds of the fuzz corpora (tests/fuzz/corpus/<target>/gen-*) with the
// project's own writers: brick and page records from real stores, manifests, node tables,
// sidecars, NRRD files, an OpenVDB export, traces in every format and .vtu files in every
// encoding. Deterministic: run again after a format changes (tests/fuzz/make_seeds.sh) and
// commit what changed.
//
// Usage: fuzz_make_seeds CORPUS_DIR

#include <zlib.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <fmt/format.h>

#include "cache/trace.h"
#include "core/raw_volume.h"
#include "fields/field.h"
#include "preprocess/builder.h"
#include "preprocess/export.h"
#include "preprocess/mesh_readers.h"
#include "preprocess/octree_builder.h"
#include "preprocess/tet_builder.h"
#include "preprocess/volume_source.h"
#include "storage/page_codec.h"
#include "storage/store.h"
#include "tests/fuzz/fuzz_util.h"

// The replay driver is not linked here: this program has its own main.
extern "C" int LLVMFuzzerTestOneInput(const uint8_t*, size_t) { return 0; }

using namespace brickyard;
namespace fs = std::filesystem;

namespace {

fs::path g_corpus;

void put(const std::string& target, const std::string& name, const void* data, size_t size) {
  const fs::path dir = g_corpus / target;
  fs::create_directories(dir);
  std::ofstream out(dir / ("gen-" + name), std::ios::binary | std::ios::trunc);
  out.write(static_cast<const char*>(data), std::streamsize(size));
  if (!out) throw Error(Errc::io, "cannot write").with_file((dir / name).string());
}
void put(const std::string& target, const std::string& name, const std::string& bytes) {
  put(target, name, bytes.data(), bytes.size());
}
std::string slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}
std::string bytes_of(std::span<const std::byte> s) { return {reinterpret_cast<const char*>(s.data()), s.size()}; }
std::string joined(std::initializer_list<std::string> files) {
  std::string out;
  for (const std::string& f : files) out += (out.empty() ? "" : std::string(fuzz::kFileSeparator)) + f;
  return out;
}

std::string build_grid(const fs::path& tmp, const std::string& name, const std::string& field, int64_t n, ValueType type,
                       int brick_size, Codec codec, bool shuffle) {
  const std::string dir = (tmp / name).string();
  auto source = make_field_source(make_field(field), Vec3s(n), type);
  BuildOptions options;
  options.brick_size = brick_size;
  options.apron = 1;
  options.codec = codec;
  options.shuffle = shuffle;
  options.check_disk = false;
  options.map_size = uint64_t(16) << 20;
  build_store(*source, dir, options);
  return dir;
}

// brick_codec: 8 bytes of parameters (the first: value type - 1), then the record (brick_codec.cpp).
void brick_seeds(const std::string& dir, const std::string& name, uint8_t type, uint8_t codec_bits, uint8_t size_index) {
  const Store store(dir);
  const auto txn = store.begin_read();
  int n = 0;
  store.for_each_record(txn, [&](const BrickKey& key, std::span<const std::byte> record) {
    if (key.x > 255 || key.y > 255 || key.z > 255) return true;
    std::string seed = {char(type), char(codec_bits), char(size_index), char(store.format().apron), char(key.level),
                        char(key.x), char(key.y), char(key.z)};
    seed += bytes_of(record);
    put("brick_codec", fmt::format("{}-{}", name, n), seed);
    return ++n < 2;
  });
}

void grid_seeds(const fs::path& tmp) {
  // Node tables: the stores node_table.cpp builds (sphere, 20^3, 8^3 bricks, apron 1).
  for (int which = 0; which < 3; ++which) {
    static constexpr ValueType kTypes[] = {ValueType::u8, ValueType::u16, ValueType::f32};
    const std::string dir = build_grid(tmp, fmt::format("nodes-{}", which), "sphere", 20, kTypes[which], 8, Codec::lz4, true);
    const Store store(dir);
    std::string seed(1, char(which));
    for (int l = 0; l < store.layout().levels; ++l) {
      const auto& r = store.nodes().level(l);
      seed.append(reinterpret_cast<const char*>(r.data()), r.size() * sizeof(NodeRecord));
    }
    put("node_table", fmt::format("{}", to_string(kTypes[which])), seed);
    if (which == 0) {
      std::string exact(1, char(0x81));  // exact mode, store 0x81 % 3 = 0
      const auto& r = store.nodes().level(0);
      exact.append(reinterpret_cast<const char*>(r.data()), r.size() * sizeof(NodeRecord));
      put("node_table", "u8-exact-level0", exact);
    }
    put("manifest", fmt::format("grid-{}.json", to_string(kTypes[which])), store.manifest().to_json());
  }
  // Bricks of every value type and codec (parameters as brick_codec.cpp reads them).
  brick_seeds(build_grid(tmp, "b-u8", "marschner-lobb", 20, ValueType::u8, 8, Codec::lz4, true), "u8-lz4", 0, 0x11, 0);
  brick_seeds(build_grid(tmp, "b-u16", "fbm", 20, ValueType::u16, 8, Codec::lz4hc, true), "u16-lz4hc-shuffled", 1, 0x12, 0);
  brick_seeds(build_grid(tmp, "b-f32", "sphere", 20, ValueType::f32, 8, Codec::none, false), "f32-none", 2, 0x00, 0);
  brick_seeds(build_grid(tmp, "b-f32s", "torus", 20, ValueType::f32, 16, Codec::lz4, true), "f32-lz4-shuffled", 2, 0x11, 1);
  // Round trips (bit 7): the voxels are the rest of the input.
  put("brick_codec", "roundtrip-f32", std::string("\x02\x91\x00\x01\x00\x00\x00\x00", 8) + "0123456789abcdef\x7f\x80\xff");
  put("brick_codec", "roundtrip-u16", std::string("\x01\x92\x00\x00\x01\x00\x00\x00", 8) + "\x01\x02\x03\x04");

  // A grid with an octree: its manifest, and octree page records (page_codec, kind bit set).
  const std::string oct = build_grid(tmp, "octree", "sphere", 24, ValueType::f32, 8, Codec::lz4, true);
  build_octree(oct, {});
  const Store store(oct);
  put("manifest", "grid-octree.json", store.manifest().to_json());
  const auto txn = store.begin_read();
  int n = 0;
  const size_t units = size_t((store.manifest().octree->page_bytes + 7) / 8);
  std::vector<std::byte> page(size_t(store.manifest().octree->page_bytes));
  store.for_each_page(txn, RecordKind::octree_page, [&](const PageKey& key, std::span<const std::byte> record) {
    // Renumbered as page 7, the id the target asks for.
    const size_t used = decode_page(key, record, page);
    const auto renumbered = encode_page(PageKey{RecordKind::octree_page, 7}, std::span(page).first(used));
    const std::string prefix = {char(2), char(units & 0xff), char(units >> 8), char(12)};
    put("page_codec", fmt::format("octree-{}", n), prefix + bytes_of(renumbered));
    return ++n < 2;
  });
}

void tet_seeds(const fs::path& tmp) {
  for (const int steps : {1, 2}) {
    ProceduralMeshSpec spec;
    spec.field = "sphere";
    spec.cells = 3;
    spec.steps = steps;
    spec.move = steps > 1 ? 0.01 : 0.0;
    auto source = make_procedural_mesh(spec, 64);
    const std::string dir = (tmp / fmt::format("tets-{}", steps)).string();
    TetBuildOptions options;
    options.cluster_tets = 64;
    options.store_bvh = steps == 1;
    options.map_size = uint64_t(16) << 20;
    build_tet_store(*source, dir, options);
    const Store store(dir);
    put("manifest", fmt::format("tets-{}-steps.json", steps), store.manifest().to_json());
    const size_t page_bytes = size_t(store.manifest().mesh.page_bytes);
    const size_t units = (page_bytes + 7) / 8;
    const auto txn = store.begin_read();
    std::vector<std::byte> page(page_bytes);
    for (uint64_t c = 0; c < std::min<uint64_t>(2, store.clusters().size()); ++c) {
      const PageKey key{RecordKind::tet_cluster, c};
      store.read_page(txn, key, page);
      // Page mode (bit 0): the decoded page, encoded again by the target as cluster 7.
      const std::string prefix = {char(1), char(units & 0xff), char(units >> 8), char(12)};
      put("page_codec", fmt::format("cluster-page-{}-steps-{}", steps, c), prefix + bytes_of(page));
      // Record mode: the record as stored, renumbered as cluster 7, the id the target asks for.
      std::vector<std::byte> record = encode_page(PageKey{RecordKind::tet_cluster, 7}, page);
      put("page_codec", fmt::format("cluster-record-{}-steps-{}", steps, c),
          std::string{char(0), char(units & 0xff), char(units >> 8), char(12)} + bytes_of(record));
    }
  }
}

void sidecar_seeds(const fs::path& tmp) {
  RawVolumeInfo a;
  a.dims = {4, 3, 2};
  a.type = ValueType::u8;
  a.bytes = 24;
  a.min_value = 0, a.max_value = 255;
  a.quantization = std::pair{-1.0, 1.0};
  a.source = "field marschner-lobb";
  a.source_params = {{"alpha", 0.25}, {"f_m", 6.0}};
  a.xxh3_64 = 0x0123456789abcdefull;
  RawVolumeInfo b;
  b.dims = {64, 32, 16};
  b.type = ValueType::f32;
  b.bytes = 64 * 32 * 16 * 4;
  b.spacing = {0.5, 1.0, 2.0};
  b.origin = {-1.0, 0.0, 10.0};
  b.min_value = -3.5, b.max_value = 7.25;
  RawVolumeInfo c;
  c.dims = {7, 1, 1};
  c.type = ValueType::u16;
  c.little_endian = false;
  c.bytes = 14;
  c.max_value = 65535;
  int n = 0;
  for (const RawVolumeInfo* info : {&a, &b, &c}) {
    const std::string path = (tmp / "s.raw.json").string();
    write_raw_sidecar(path, *info);
    put("raw_sidecar", fmt::format("{}.raw.json", n++), slurp(path));
  }
}

std::string gzip(const std::string& data) {
  z_stream z{};
  deflateInit2(&z, 9, Z_DEFLATED, 15 + 16, 8, Z_DEFAULT_STRATEGY);
  std::string out(deflateBound(&z, uLong(data.size())) + 32, '\0');
  z.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(data.data()));
  z.avail_in = uInt(data.size());
  z.next_out = reinterpret_cast<Bytef*>(out.data());
  z.avail_out = uInt(out.size());
  deflate(&z, Z_FINISH);
  out.resize(z.total_out);
  deflateEnd(&z);
  return out;
}

void nrrd_seeds() {
  std::string u8(24, '\0');
  for (size_t i = 0; i < u8.size(); ++i) u8[i] = char(i * 10);
  put("nrrd", "u8-raw.nrrd", "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 4 3 2\nencoding: raw\n\n" + u8);
  std::string be16;
  for (int i = 0; i < 12; ++i) be16 += {char(i >> 8), char(i * 20)};
  put("nrrd", "u16-big-spacings.nrrd",
      "NRRD0004\n# a comment\ntype: unsigned short\ndimension: 3\nsizes: 2 3 2\nendian: big\nencoding: raw\n"
      "spacings: 0.5 1 2\nspace origin: (1,2,3)\nkey:=value\n\n" + be16);
  std::string f32(2 * 2 * 3 * 4, '\0');
  for (int i = 0; i < 12; ++i) {
    const float v = float(i) * 0.25f - 1.0f;
    std::memcpy(f32.data() + 4 * i, &v, 4);
  }
  put("nrrd", "f32-directions.nrrd",
      "NRRD0005\ntype: float\ndimension: 3\nspace: right-anterior-superior\nsizes: 2 2 3\nendian: little\n"
      "encoding: raw\nspace directions: (1,0,0) (0,2,0) (0,0,0.5)\nspace origin: (0,0,0)\n\n" + f32);
  std::string f64(2 * 2 * 2 * 8, '\0');
  for (int i = 0; i < 8; ++i) {
    const double v = std::sin(double(i));
    std::memcpy(f64.data() + 8 * i, &v, 8);
  }
  put("nrrd", "f64-converted.nrrd", "NRRD0004\ntype: double\ndimension: 3\nsizes: 2 2 2\nendian: little\nencoding: raw\n\n" + f64);
  std::string i16(3 * 2 * 2 * 2, '\0');
  for (int i = 0; i < 12; ++i) i16[size_t(2 * i)] = char(-i), i16[size_t(2 * i + 1)] = char(i % 2 ? 0xff : 0);
  put("nrrd", "i16-gzip.nrrd",
      "NRRD0004\ntype: short\ndimension: 3\nsizes: 3 2 2\nendian: little\nencoding: gzip\n\n" + gzip(i16));
  put("nrrd", "u8-gzip.nrrd", "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 4 3 2\nencoding: gz\n\n" + gzip(u8));
  put("nrrd", "u8-detached.nrrd",
      joined({"NRRD0004\ntype: uchar\ndimension: 3\nsizes: 4 3 2\nencoding: raw\ndata file: data.raw\n", u8}));
  put("nrrd", "u8-byteskip.nrrd",
      joined({"NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 3 2\nencoding: raw\nbyte skip: -1\ndatafile: data.raw\n", u8}));
  put("nrrd", "i32-byteskip.nrrd",
      joined({"NRRD0004\ntype: int\ndimension: 3\nsizes: 1 1 2\nendian: little\nencoding: raw\nbyte skip: 16\n"
              "data file: data.raw\n", u8}));
}

void vdb_seeds(const fs::path& tmp) {
  if (!vdb_support()) return;
  const std::string dir = build_grid(tmp, "vdb", "sphere", 12, ValueType::f32, 8, Codec::lz4, true);
  const Store store(dir);
  const std::string path = (tmp / "grid.vdb").string();
  export_vdb(store, store.layout().finest(), export_region(store, store.layout().finest(), std::nullopt), path, "density");
  put("vdb", "sphere.vdb", slurp(path));
  export_vdb(store, 0, export_region(store, 0, std::nullopt), path, "coarse");
  put("vdb", "sphere-coarse.vdb", slurp(path));
}

void trace_seeds(const fs::path& tmp) {
  Trace zipf = zipf_trace(24, 80, 0.9, 7, 4096);
  Trace mixed;
  for (uint32_t i = 0; i < 40; ++i) {
    TraceRecord r;
    r.key = (i * 7) % 13;
    r.frame = i / 8;
    r.size = 512u << (i % 3);
    r.kind = AccessKind(i % 4);
    r.hit_level = uint8_t(i % 4);
    r.thread = i % 3;
    r.record = RecordKind(i % 3);
    mixed.records.push_back(r);
  }
  struct Out {
    const char* target;
    TraceFormat format;
    const char* ext;
  };
  for (const Out& o : {Out{"trace_bytrace", TraceFormat::brickyard, "bytrace"},
                       Out{"trace_oracle", TraceFormat::oracle_general, "oracleGeneral"},
                       Out{"trace_text", TraceFormat::text, "txt"}}) {
    int n = 0;
    for (const Trace* t : {&zipf, &mixed}) {
      const std::string path = (tmp / fmt::format("t.{}", o.ext)).string();
      write_trace(path, *t, o.format);
      put(o.target, fmt::format("{}.{}", n++ ? "mixed" : "zipf", o.ext), slurp(path));
    }
  }
}

TetMesh small_mesh(size_t n) {
  TetMesh m;
  for (size_t i = 0; i < n; ++i) {
    const float t = float(i) * 0.37f;
    m.positions.insert(m.positions.end(), {std::cos(t), std::sin(t), t * 0.01f});
  }
  for (size_t i = 0; i + 3 < n; ++i) m.tets.insert(m.tets.end(), {uint32_t(i), uint32_t(i + 1), uint32_t(i + 2), uint32_t(i + 3)});
  m.scalars.resize(2);
  for (size_t i = 0; i < n; ++i) {
    m.scalars[0].push_back(float(i) * 0.5f - 3.25f);
    m.scalars[1].push_back(1.0f / float(i + 1));
  }
  m.array_name = "density";
  m.step_names = {"density_0", "density_1"};
  return m;
}

void mesh_seeds(const fs::path& tmp) {
  using E = VtuWriteOptions::Encoding;
  const TetMesh mesh = small_mesh(7);
  const std::string path = (tmp / "m.vtu").string();
  int n = 0;
  for (const E encoding : {E::ascii, E::binary, E::appended_raw, E::appended_base64})
    for (const bool compress : {false, true}) {
      write_vtu(path, mesh, {encoding, compress, /*header64=*/(n % 3) == 1});
      put("mesh_vtu", fmt::format("written-{}.vtu", n++), slurp(path));
    }
  // A collection of two steps (the files the target writes: mesh.pvd, a.vtu, b.vtu).
  TetMesh one = small_mesh(6);
  one.scalars.resize(1);
  one.step_names = {"density"};
  write_vtu(path, one, {E::ascii, false, false});
  const std::string a = slurp(path);
  write_vtu(path, one, {E::appended_raw, true, false});
  const std::string b = slurp(path);
  const std::string pvd =
      "<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"0.1\">\n  <Collection>\n"
      "    <DataSet timestep=\"0\" part=\"0\" file=\"a.vtu\"/>\n    <DataSet timestep=\"0.5\" part=\"0\" file=\"b.vtu\"/>\n"
      "  </Collection>\n</VTKFile>\n";
  put("mesh_pvd", "two-steps", joined({pvd, a, b}));
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: %s CORPUS_DIR\n", argv[0]);
    return 2;
  }
  g_corpus = argv[1];
  try {
    const fs::path tmp = fuzz::temp_dir();
    grid_seeds(tmp);
    tet_seeds(tmp);
    sidecar_seeds(tmp);
    nrrd_seeds();
    vdb_seeds(tmp);
    trace_seeds(tmp);
    mesh_seeds(tmp);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "fuzz_make_seeds: %s\n", e.what());
    return 1;
  }
  return 0;
}
