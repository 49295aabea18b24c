// The bad-input census's table: one function per area, each a list of distinct bad inputs with
// the exit code and the part of the message that names the file, key or field. See census.h.

#include <sys/stat.h>

#include <cstdlib>
#include <filesystem>
#include <functional>
#include <limits>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "census.h"
#include "core/brick_key.h"
#include "core/error.h"
#include "fields/field.h"
#include "preprocess/builder.h"
#include "preprocess/volume_source.h"
#include "storage/lmdb_env.h"
#include "storage/store.h"
#include "storage/store_lock.h"
#include "store_damage.h"
#include "stops_halfway.h"
#include "test_util.h"

namespace brickyard::census {
namespace {

namespace fs = std::filesystem;

// ---- Setup helpers -------------------------------------------------------------------------

const std::string kSmall = R"("image": {"width": 16, "height": 16})";
const std::string kCam = R"("camera": {"eye": [1.8, -1.2, 1.4], "target": [0.5, 0.5, 0.5]})";
const std::string kIso = R"("mode": "iso", "isosurfaces": [{"value": 0.0}])";
const std::string kTf = R"("transfer_function": {"points": [{"value": 0.1, "color": [1, 1, 1], "opacity": 0.5},)"
                        R"( {"value": 0.5, "color": [1, 1, 1], "opacity": 0.5}]})";

/// Writes a scene of `dataset` (relative to the scene); a 16x16 image unless `members` sets one.
Setup scene(const std::string& name, const std::string& members, const std::string& dataset = "grid.store") {
  return [=](const Workspace& ws) {
    const std::string image = members.find("\"image\"") == std::string::npos ? kSmall + ", " : "";
    ws.write(name, "{\"dataset\": \"" + dataset + "\", " + image + members + "}\n");
  };
}

/// A copy of the 16^3 u8 raw file with a sidecar edited by `edit`.
Setup sidecar(const std::string& name, std::function<void(nlohmann::json&)> edit) {
  return [=](const Workspace& ws) {
    ws.write(name + ".raw", ws.read("s.raw"));
    nlohmann::json j = nlohmann::json::parse(ws.read("s.raw.json"));
    edit(j);
    ws.write(name + ".raw.json", j.dump(2));
  };
}

/// A NRRD file: `header` (lines, without the blank line that ends it) then the 16^3 u8 voxels.
Setup nrrd(const std::string& name, const std::string& header, bool data = true) {
  return [=](const Workspace& ws) { ws.write(name, header + "\n" + (data ? ws.read("s.raw") : std::string())); };
}

Setup text(const std::string& name, const std::string& content) {
  return [=](const Workspace& ws) { ws.write(name, content); };
}

Setup copy_store(const std::string& from, const std::string& to, std::function<void(const std::string&)> damage = {}) {
  return [=](const Workspace& ws) {
    ws.copy_store(from, to);
    if (damage) damage(ws.file(to));
  };
}

/// The brick trace written by the fixture, with one byte set to `value`.
Setup trace_with_byte(const std::string& name, size_t at, char value) {
  return [=](const Workspace& ws) {
    std::string t = ws.read("good.bytrace");
    t[at] = value;
    ws.write(name, t);
  };
}

/// Deletes a record from one of a store's databases, as a lost write would.
void erase_record(const std::string& store, const std::string& database, const std::vector<std::byte>& key) {
  lmdb::Env env(store, {});
  const lmdb::Database db = env.open_database(database, false);
  lmdb::BatchWriter writer(env);
  writer.erase(db, key);
  writer.commit();
}

/// Rewrites the manifest's format version, and drops its checksum as a build that wrote none.
void set_format_version(const std::string& store, int version) {
  lmdb::Env env(store, {});
  const lmdb::Database db = env.open_database(kManifestDb, false);
  std::string manifest;
  {
    lmdb::ReadTxn txn(env);
    const auto v = txn.get(db, lmdb::as_bytes("manifest"));
    ASSERT_TRUE(v.has_value()) << store;
    manifest.assign(reinterpret_cast<const char*>(v->data()), v->size());
  }
  const std::string from = "\"format_version\": 1";
  const size_t at = manifest.find(from);
  ASSERT_NE(at, std::string::npos) << manifest;
  manifest.replace(at, from.size(), "\"format_version\": " + std::to_string(version));
  lmdb::BatchWriter writer(env);
  writer.put(db, lmdb::as_bytes("manifest"), lmdb::as_bytes(manifest));
  writer.erase(db, lmdb::as_bytes("manifest.xxh3"));
  writer.commit();
}

std::vector<std::byte> bytes_of(const std::string& s) {
  return {reinterpret_cast<const std::byte*>(s.data()), reinterpret_cast<const std::byte*>(s.data() + s.size())};
}

Setup interrupted_store(const std::string& name) {
  return [=](const Workspace& ws) {
    testing::StopsHalfway source;
    BuildOptions o;
    o.brick_size = 16;
    EXPECT_THROW(build_store(source, ws.file(name), o), Error);
    ASSERT_EQ(probe_store(ws.file(name)), StoreState::incomplete);
  };
}

/// The finest brick facing the census's camera in grid.store (32^3 in 16^3 bricks).
const BrickKey kFacingBrick{1, 1, 0, 1};
void damage_facing_brick(const std::string& store) { testing::damage_record(store, kBricksDb, kFacingBrick.code()); }


// ---- The cases ---------------------------------------------------------------------------

const std::string raw16 = "$TMP/s.raw --dims 16 --type u8";  // a valid raw import, to vary one option of
const std::string flight = "brickyard flight $TMP/grid.store --path $TMP/path.json ";
const std::string render = "brickyard -q render $TMP/ok.json ";
const std::string bench = "brickyard -q bench $TMP/ok.json --backends raymarch --warm 1 --cold 0 ";
const std::string nrrd_head = "NRRD0004\ntype: uint8\ndimension: 3\n";
const std::string cachebench = "brickyard cachebench $TMP/good.bytrace --policies lru --sizes 50% ";

void add_cli_cases(std::vector<Case>& c) {
  // --- cli: global options and generate
  c.push_back({"cli", "no subcommand", {}, "brickyard", 2, "a subcommand is required (generate, version, import"});
  c.push_back({"cli", "unknown subcommand", {}, "brickyard frobnicate", 2, "not expected: frobnicate"});
  c.push_back({"cli", "unknown option", {}, "brickyard generate sphere --bogus --out $TMP/g.raw", 2, "not expected: --bogus"});
  c.push_back({"cli", "--threads out of range", {}, "brickyard --threads 0 version", 2, "--threads: Value 0 not in range"});
  c.push_back({"cli", "--module file missing", {}, "brickyard --module $TMP/none.so version", 1, "$TMP/none.so: no such module file"});
  c.push_back({"cli", "--module not a shared library", {}, "brickyard --module $TMP/s.raw version", 1,
               "$TMP/s.raw: cannot load the module"});
  c.push_back({"cli", "--size zero", {}, "brickyard generate sphere --size 0 --out $TMP/g.raw", 2,
               "field '--size': '0': every dimension must be at least 1"});
  c.push_back({"cli", "--size not a number", {}, "brickyard generate sphere --size abc --out $TMP/g.raw", 2,
               "field '--size': 'abc' is not a size"});
  c.push_back({"cli", "--size with two dimensions", {}, "brickyard generate sphere --size 12,13 --out $TMP/g.raw", 2,
               "field '--size': '12,13' has 2 dimensions; give 1 or 3"});
  c.push_back({"cli", "--size overflows a byte count", {}, "brickyard generate sphere --size 10000000 --out $TMP/g.raw", 2,
               "overflow a 64-bit byte count"});
  c.push_back({"cli", "BRICKYARD_AVAILABLE_MEMORY not a size", {},
               "BRICKYARD_AVAILABLE_MEMORY=12XB brickyard -q render $TMP/ok.json -o $TMP/x.png", 2,
               "field 'BRICKYARD_AVAILABLE_MEMORY': '12XB' is not a size"});
  c.push_back({"cli", "unknown field", {}, "brickyard generate perlin --out $TMP/g.raw", 2,
               "unknown field 'perlin' (known fields: marschner-lobb"});
  c.push_back({"cli", "unknown value type", {}, "brickyard generate sphere --type f64 --out $TMP/g.raw", 2, "unknown value type 'f64'"});
  c.push_back({"cli", "unknown field parameter", {}, "brickyard generate sphere --set radiu=0.2 --out $TMP/g.raw", 2,
               "field 'sphere' has no parameter 'radiu'"});
  c.push_back({"cli", "field parameter without a value", {}, "brickyard generate sphere --set radius --out $TMP/g.raw", 2,
               "'radius' is not NAME=VALUE"});
  c.push_back({"cli", "field parameter not a number", {}, "brickyard generate sphere --set radius=big --out $TMP/g.raw", 2,
               "'big' is not a finite number"});
  c.push_back({"cli", "generate without --out", {}, "brickyard generate sphere --size 8", 2, "missing output file"});
  c.push_back({"cli", "generate without a field", {}, "brickyard generate --size 8 --out $TMP/g.raw", 2, "missing FIELD"});
  c.push_back({"cli", "output directory missing", {}, "brickyard generate sphere --size 8 --out $TMP/nodir/g.raw", 1,
               "$TMP/nodir: the output directory does not exist"});

  c.push_back({"cli", "generate larger than the free disk", {},
               "BRICKYARD_AVAILABLE_DISK=1GiB brickyard generate sphere --size 2048 --type f32 --out $TMP/g.raw", 4,
               "generate of 2048x2048x2048 f32 needs up to 32 GiB of disk (the raw file), but 1 GiB is free there"});
  c.push_back({"cli", "BRICKYARD_AVAILABLE_DISK not a size", {},
               "BRICKYARD_AVAILABLE_DISK=12XB brickyard generate sphere --size 8 --out $TMP/g.raw", 2,
               "field 'BRICKYARD_AVAILABLE_DISK': '12XB' is not a size"});
}

void add_import_cases(std::vector<Case>& c) {
  // --- import: raw files, sidecars, NRRD, OpenVDB, fields
  c.push_back({"import", "raw shorter than --dims", text("short.raw", std::string(1000, '\1')),
               "brickyard import $TMP/short.raw --dims 16 --type u8 --out $TMP/i.store", 1,
               "$TMP/short.raw: field 'dims': file is truncated: 1000 bytes, but 16x16x16 u8 needs 4096"});
  c.push_back({"import", "raw longer than --dims", {}, "brickyard import $TMP/s.raw --dims 8 --type u8 --out $TMP/i.store", 1,
               "$TMP/s.raw: field 'dims': file is larger than its dims say"});
  c.push_back({"import", "--dims overflow a byte count", {},
               "brickyard import $TMP/s.raw --dims 4000000000,4000000000,4000000000 --type u16 --out $TMP/i.store", 2,
               "overflow a 64-bit byte count"});
  c.push_back({"import", "raw without sidecar or --dims", text("bare.raw", std::string(64, '\1')),
               "brickyard import $TMP/bare.raw --out $TMP/i.store", 2, "needs --dims and --type, or a sidecar"});
  c.push_back({"import", "raw file missing", {}, "brickyard import $TMP/nothing.raw --dims 4 --type u8 --out $TMP/i.store", 1,
               "$TMP/nothing.raw: cannot open"});
  c.push_back({"import", "unknown --codec", {}, "brickyard import " + raw16 + " --codec zstd --out $TMP/i.store", 2,
               "unknown codec 'zstd'"});
  c.push_back({"import", "--brick-size not a power of two", {}, "brickyard import " + raw16 + " --brick-size 24 --out $TMP/i.store",
               2, "not a power of two in [8, 128]"});
  c.push_back({"import", "--apron too wide", {}, "brickyard import " + raw16 + " --apron 5 --out $TMP/i.store", 2,
               "field '--apron': apron 5 is outside [0, 4]"});
  c.push_back({"import", "unknown --downsample", {}, "brickyard import " + raw16 + " --downsample median --out $TMP/i.store", 2,
               "field '--downsample': unknown filter 'median'"});
  c.push_back({"import", "--level-set with averaged levels", {},
               "brickyard import " + raw16 + " --level-set --downsample average --out $TMP/i.store", 2,
               "field '--downsample': --level-set keeps the zero crossing"});
  c.push_back({"import", "unknown --nonfinite", {}, "brickyard import " + raw16 + " --nonfinite ignore --out $TMP/i.store", 2,
               "field '--nonfinite': unknown repair 'ignore'"});
  c.push_back({"import", "--range with LO > HI", {}, "brickyard import " + raw16 + " --range 5,1 --out $TMP/i.store", 2,
               "'5,1' is not LO,HI"});
  c.push_back({"import", "unknown --endian", {}, "brickyard import " + raw16 + " --endian middle --out $TMP/i.store", 2,
               "field '--endian': 'middle' is neither little nor big"});
  c.push_back({"import", "--origin not X,Y,Z", {}, "brickyard import " + raw16 + " --origin a,b,c --out $TMP/i.store", 2,
               "field '--origin': 'a,b,c' is not X,Y,Z"});
  c.push_back({"import", "--transaction-size zero", {}, "brickyard import " + raw16 + " --transaction-size 0 --out $TMP/i.store", 2,
               "field '--transaction-size'"});
  c.push_back({"import", "--constant-tolerance below zero", {},
               "brickyard import " + raw16 + " --constant-tolerance -1 --out $TMP/i.store", 2, "field '--constant-tolerance'"});
  c.push_back({"import", "unknown raw --type", {}, "brickyard import $TMP/s.raw --dims 16 --type u64 --out $TMP/i.store", 2,
               "field '--type': unknown value type 'u64' (expected u8, i8, u16, i16, f32, or u32, i32, f64"});
  c.push_back({"import", "32-bit integers that f32 would round",
               [](const Workspace& ws) {
                 std::vector<uint32_t> v(4 * 4 * 4, 7);
                 v[9] = (1u << 24) + 3;
                 ws.write("wide.raw", std::string(reinterpret_cast<const char*>(v.data()), v.size() * 4));
               },
               "brickyard import $TMP/wide.raw --dims 4 --type u32 --out $TMP/i.store", 2,
               "$TMP/wide.raw: field '--convert': 1 of its u32 values exceed 2^24 in magnitude"});
  c.push_back({"import", "doubles beyond the float range",
               [](const Workspace& ws) {
                 std::vector<double> v(4 * 4 * 4, 0.5);
                 v[2] = 1e300;
                 ws.write("huge.raw", std::string(reinterpret_cast<const char*>(v.data()), v.size() * 8));
               },
               "brickyard import $TMP/huge.raw --dims 4 --type f64 --out $TMP/i.store", 1,
               "$TMP/huge.raw: field 'type': 1 of its f64 values lie beyond the largest float"});
  c.push_back({"import", "unknown --convert", {}, "brickyard import " + raw16 + " --convert f16 --out $TMP/i.store", 2,
               "field '--convert': 'f16' is not a conversion brickyard makes"});
  c.push_back({"import", "--convert for a field", {}, "brickyard import field:sphere --convert f32 --out $TMP/i.store", 2,
               "field '--convert': does not apply to a field: source"});
  c.push_back({"import", "--background not a number", {}, "brickyard import " + raw16 + " --background air --out $TMP/i.store", 2,
               "field '--background': 'air' is not a number"});
  c.push_back({"import", "NaN voxels",
               [](const Workspace& ws) {
                 std::vector<float> v(8 * 8 * 8, 1.0f);
                 v[3 + 8 * (2 + 8 * 1)] = std::numeric_limits<float>::quiet_NaN();  // (3, 2, 1)
                 ws.write("nan.raw", std::string(reinterpret_cast<const char*>(v.data()), v.size() * 4));
               },
               "brickyard import $TMP/nan.raw --dims 8 --type f32 --out $TMP/i.store", 1,
               "1 non-finite voxels (NaN or infinity), the first at (3, 2, 1)"});
  c.push_back({"import", "map full without growth", {},
               "brickyard -q import field:fbm --size 96 --type f32 --map-size 256KiB --no-map-growth --out $TMP/full.store", 4,
               "store is full"});
  c.push_back({"import", "--map-size too small for the manifest", {}, "brickyard import " + raw16 + " --map-size 1 --out $TMP/tiny.store",
               4, "$TMP/tiny.store: mdb_dbi_open failed: MDB_MAP_FULL"});
  c.push_back({"import", "--out is a regular file", {}, "brickyard import " + raw16 + " --out $TMP/afile", 2,
               "$TMP/afile: exists and is not a brickyard store"});
  c.push_back({"import", "other parameters without --force", {},
               "brickyard import field:sphere --size 32 --type f32 --brick-size 32 --out $TMP/grid.store", 2,
               "$TMP/grid.store: a complete store from a different source or with different parameters is there; pass --force"});
  c.push_back({"import", "another writer holds the store",
               [](const Workspace& ws) { ws.hold(std::make_shared<StoreWriteLock>(ws.file("held.store"))); },
               "brickyard import " + raw16 + " --out $TMP/held.store", 1, "$TMP/held.store: another writer (pid $PID) holds this store"});
  c.push_back({"import", "larger than the free disk", {},
               "BRICKYARD_AVAILABLE_DISK=1GiB brickyard import field:fbm --size 8192 --type u8 --out $TMP/i.store", 4,
               "$TMP/i.store: import of 8192x8192x8192 u8 needs up to"});
  c.push_back({"import", "larger than the free memory", {},
               "BRICKYARD_AVAILABLE_MEMORY=1GiB brickyard import field:fbm --size 8192 --type u8 --no-disk-check --out $TMP/i.store", 4,
               "of memory"});
  c.push_back({"import", "sidecar: dims of the wrong type", sidecar("sc_dims_type", [](nlohmann::json& j) { j["dims"] = "16x16x16"; }),
               "brickyard import $TMP/sc_dims_type.raw --out $TMP/i.store", 1, "$TMP/sc_dims_type.raw.json: field 'dims': expected an array, each element an integer, found a string"});
  c.push_back({"import", "sidecar: dims missing", sidecar("sc_no_dims", [](nlohmann::json& j) { j.erase("dims"); }),
               "brickyard import $TMP/sc_no_dims.raw --out $TMP/i.store", 1, "$TMP/sc_no_dims.raw.json: field 'dims': missing key"});
  c.push_back({"import", "sidecar: two dims", sidecar("sc_dims2", [](nlohmann::json& j) { j["dims"] = {16, 16}; }),
               "brickyard import $TMP/sc_dims2.raw --out $TMP/i.store", 1, "$TMP/sc_dims2.raw.json: field 'dims': expected 3 numbers"});
  c.push_back({"import", "sidecar: negative dimension", sidecar("sc_neg", [](nlohmann::json& j) { j["dims"] = {16, 16, -16}; }),
               "brickyard import $TMP/sc_neg.raw --out $TMP/i.store", 1, "$TMP/sc_neg.raw.json: field 'dims'"});
  c.push_back({"import", "sidecar: unknown type", sidecar("sc_type", [](nlohmann::json& j) { j["type"] = "f64"; }),
               "brickyard import $TMP/sc_type.raw --out $TMP/i.store", 1,
               "$TMP/sc_type.raw.json: field 'type': unknown value type 'f64'"});
  c.push_back({"import", "sidecar: newer version", sidecar("sc_version", [](nlohmann::json& j) { j["brickyard_raw"] = 7; }),
               "brickyard import $TMP/sc_version.raw --out $TMP/i.store", 1,
               "$TMP/sc_version.raw.json: field 'brickyard_raw': sidecar version 7 is newer"});
  c.push_back({"import", "sidecar: unknown endianness", sidecar("sc_endian", [](nlohmann::json& j) { j["endianness"] = "middle"; }),
               "brickyard import $TMP/sc_endian.raw --out $TMP/i.store", 1, "$TMP/sc_endian.raw.json: field 'endianness'"});
  c.push_back({"import", "sidecar: bytes disagree with dims", sidecar("sc_bytes", [](nlohmann::json& j) { j["bytes"] = 5000; }),
               "brickyard import $TMP/sc_bytes.raw --out $TMP/i.store", 1,
               "$TMP/sc_bytes.raw.json: field 'bytes': 5000 bytes does not match dims 16x16x16"});
  c.push_back({"import", "sidecar: not valid JSON", text("sc_json.raw.json", R"({"dims": [16, 16, 16], "type": "u8")"),
               "brickyard import $TMP/sc_json.raw --out $TMP/i.store", 1, "$TMP/sc_json.raw.json: not valid JSON"});
}

void add_nrrd_and_vdb_cases(std::vector<Case>& c) {
  c.push_back({"import", "NRRD: no magic", nrrd("magic.nrrd", "NRRX0004\ntype: uint8\ndimension: 3\nsizes: 16 16 16\nencoding: raw\n"),
               "brickyard import $TMP/magic.nrrd --out $TMP/i.store", 1, "$TMP/magic.nrrd: not a NRRD file"});
  c.push_back({"import", "NRRD: unsupported type",
               nrrd("type.nrrd", "NRRD0004\ntype: complex\ndimension: 3\nsizes: 16 16 16\nencoding: raw\n"),
               "brickyard import $TMP/type.nrrd --out $TMP/i.store", 1, "$TMP/type.nrrd: field 'type': NRRD type 'complex'"});
  c.push_back({"import", "NRRD: two dimensions", nrrd("dim.nrrd", "NRRD0004\ntype: uint8\ndimension: 2\nsizes: 64 64\nencoding: raw\n"),
               "brickyard import $TMP/dim.nrrd --out $TMP/i.store", 1, "$TMP/dim.nrrd: field 'dimension'"});
  c.push_back({"import", "NRRD: two sizes", nrrd("sizes.nrrd", nrrd_head + "sizes: 16 16\nencoding: raw\n"),
               "brickyard import $TMP/sizes.nrrd --out $TMP/i.store", 1, "$TMP/sizes.nrrd: field 'sizes'"});
  c.push_back({"import", "NRRD: sizes missing", nrrd("nosizes.nrrd", nrrd_head + "encoding: raw\n"),
               "brickyard import $TMP/nosizes.nrrd --out $TMP/i.store", 1, "$TMP/nosizes.nrrd: field 'sizes': missing required field"});
  c.push_back({"import", "NRRD: unsupported encoding", nrrd("enc.nrrd", nrrd_head + "sizes: 16 16 16\nencoding: bzip2\n"),
               "brickyard import $TMP/enc.nrrd --out $TMP/i.store", 1, "$TMP/enc.nrrd: field 'encoding': encoding 'bzip2'"});
  c.push_back({"import", "NRRD: 16-bit data without endian",
               nrrd("endian.nrrd", "NRRD0004\ntype: uint16\ndimension: 3\nsizes: 16 16 8\nencoding: raw\n"),
               "brickyard import $TMP/endian.nrrd --out $TMP/i.store", 1, "$TMP/endian.nrrd: field 'endian': missing required field"});
  c.push_back({"import", "NRRD: unknown endian",
               nrrd("endianv.nrrd", "NRRD0004\ntype: uint16\ndimension: 3\nsizes: 16 16 8\nendian: middle\nencoding: raw\n"),
               "brickyard import $TMP/endianv.nrrd --out $TMP/i.store", 1, "$TMP/endianv.nrrd: field 'endian'"});
  c.push_back({"import", "NRRD: two spacings", nrrd("spacings.nrrd", nrrd_head + "sizes: 16 16 16\nspacings: 1 1\nencoding: raw\n"),
               "brickyard import $TMP/spacings.nrrd --out $TMP/i.store", 1, "$TMP/spacings.nrrd: field 'spacings': expected 3 spacings"});
  c.push_back({"import", "NRRD: a spacing not a number",
               nrrd("spacingx.nrrd", nrrd_head + "sizes: 16 16 16\nspacings: 1 x 1\nencoding: raw\n"),
               "brickyard import $TMP/spacingx.nrrd --out $TMP/i.store", 1, "$TMP/spacingx.nrrd: field 'spacings': 'x' is not a number"});
  c.push_back({"import", "NRRD: two space directions",
               nrrd("sd.nrrd", nrrd_head + "sizes: 16 16 16\nspace directions: (1,0,0) (0,1,0)\nencoding: raw\n"),
               "brickyard import $TMP/sd.nrrd --out $TMP/i.store", 1, "$TMP/sd.nrrd: field 'space directions'"});
  c.push_back({"import", "NRRD: a 2D space origin",
               nrrd("origin.nrrd", nrrd_head + "sizes: 16 16 16\nspace origin: (0,0)\nencoding: raw\n"),
               "brickyard import $TMP/origin.nrrd --out $TMP/i.store", 1, "$TMP/origin.nrrd: field 'space origin'"});
  c.push_back({"import", "NRRD: header line without a colon",
               nrrd("line.nrrd", "NRRD0004\ntype uint8\ndimension: 3\nsizes: 16 16 16\nencoding: raw\n"),
               "brickyard import $TMP/line.nrrd --out $TMP/i.store", 1, "$TMP/line.nrrd: malformed header line 'type uint8'"});
  c.push_back({"import", "NRRD: header never ends", text("noend.nrrd", nrrd_head + "sizes: 16 16 16\nencoding: raw\n"),
               "brickyard import $TMP/noend.nrrd --out $TMP/i.store", 1, "$TMP/noend.nrrd: header never ends"});
  c.push_back({"import", "NRRD: data truncated",
               [](const Workspace& ws) {
                 ws.write("trunc.nrrd", nrrd_head + "sizes: 16 16 16\nencoding: raw\n\n" + std::string(100, '\1'));
               },
               "brickyard import $TMP/trunc.nrrd --out $TMP/i.store", 1, "$TMP/trunc.nrrd: field 'sizes': data is truncated"});
  c.push_back({"import", "NRRD: gzip encoding with no data", nrrd("gzip.nrrd", nrrd_head + "sizes: 16 16 16\nencoding: gzip\n", false),
               "brickyard import $TMP/gzip.nrrd --out $TMP/i.store", 1, "$TMP/gzip.nrrd"});
  c.push_back({"import", "NRRD: byte skip -1 with gzip", nrrd("skip.nrrd", nrrd_head + "sizes: 16 16 16\nbyte skip: -1\nencoding: gzip\n"),
               "brickyard import $TMP/skip.nrrd --out $TMP/i.store", 1,
               "$TMP/skip.nrrd: field 'byte skip': byte skip -1 needs raw encoding"});
  c.push_back({"import", "NRRD: detached data file missing",
               text("detached.nhdr", nrrd_head + "sizes: 16 16 16\nencoding: raw\ndata file: nothere.raw\n"),
               "brickyard import $TMP/detached.nhdr --out $TMP/i.store", 1, "nothere.raw"});
  c.push_back({"import", "NRRD: multi-file data", text("list.nhdr", nrrd_head + "sizes: 16 16 16\nencoding: raw\ndata file: LIST\n"),
               "brickyard import $TMP/list.nhdr --out $TMP/i.store", 1, "$TMP/list.nhdr: field 'data file': multi-file data"});
  c.push_back({"import", "OpenVDB: not a VDB file", text("bad.vdb", "not a vdb\n"), "brickyard import $TMP/bad.vdb --out $TMP/i.store", 1,
               "$TMP/bad.vdb: not a readable OpenVDB file", true});
  c.push_back({"import", "OpenVDB: --grid names no grid",
               [](const Workspace& ws) {
                 const auto r = testing::run_command(kExe + " -q export " + ws.file("grid.store") + " --out " + ws.file("g.vdb"));
                 ASSERT_EQ(r.exit_code, 0) << r.output;
               },
               "brickyard import $TMP/g.vdb --grid nope --out $TMP/i.store", 1, "$TMP/g.vdb: field '--grid': no grid named 'nope'",
               true});

  c.push_back({"import", "--spacing zero", {}, "brickyard import " + raw16 + " --spacing 0,0,0 --out $TMP/i.store", 2,
               "field '--spacing': spacing (0, 0, 0): every axis needs a positive, finite distance between samples"});
  c.push_back({"import", "sidecar: a spacing of zero", sidecar("sc_spacing", [](nlohmann::json& j) { j["spacing"] = {1, 0, 1}; }),
               "brickyard import $TMP/sc_spacing.raw --out $TMP/i.store", 1,
               "$TMP/sc_spacing.raw.json: field 'spacing': spacing (1, 0, 1)"});
  c.push_back({"import", "sidecar: unknown key", sidecar("sc_key", [](nlohmann::json& j) { j["spacng"] = {1, 1, 1}; }),
               "brickyard import $TMP/sc_key.raw --out $TMP/i.store", 1, "$TMP/sc_key.raw.json: field 'spacng': unknown key"});
  c.push_back({"import", "sidecar: checksum of another file",
               [](const Workspace& ws) {
                 std::string data = ws.read("s.raw");
                 data[100] = char(data[100] ^ 1);
                 ws.write("sc_sum.raw", data);
                 ws.write("sc_sum.raw.json", ws.read("s.raw.json"));
               },
               "brickyard import $TMP/sc_sum.raw --out $TMP/i.store", 1,
               "$TMP/sc_sum.raw: field 'xxh3_64': the file's XXH3-64 is"});
  c.push_back({"import", "raw file is a FIFO", [](const Workspace& ws) { ASSERT_EQ(::mkfifo(ws.file("fifo.raw").c_str(), 0600), 0); },
               "brickyard import $TMP/fifo.raw --dims 4 --type u8 --out $TMP/i.store", 1,
               "$TMP/fifo.raw: is a FIFO, not a file: inputs are read from regular files"});
  c.push_back({"import", "raw options for a directory (a DICOM series)", {},
               "brickyard import $TMP/plain --dims 4 --type u8 --out $TMP/i.store", 2,
               "field '--dims': does not apply to a DICOM series ($TMP/plain), and would be ignored"});
  c.push_back({"import", "--header-bytes overflow a size", {},
               "brickyard import " + raw16 + " --header-bytes 18446744073709551615 --out $TMP/i.store", 2,
               "field '--header-bytes': a 18446744073709551615-byte header and 4096 bytes of voxels overflow a 64-bit size"});
  c.push_back({"import", "a raw option for a field", {}, "brickyard import field:sphere --dims 4 --out $TMP/i.store", 2,
               "field '--dims': does not apply to a field: source (field:sphere), and would be ignored"});
  c.push_back({"import", "a field option for a raw file", {}, "brickyard import " + raw16 + " --size 64 --out $TMP/i.store", 2,
               "field '--size': does not apply to a raw file"});
  c.push_back({"import", "NRRD: a spacing of zero", nrrd("spacing0.nrrd", nrrd_head + "sizes: 16 16 16\nspacings: 1 0 1\nencoding: raw\n"),
               "brickyard import $TMP/spacing0.nrrd --out $TMP/i.store", 1, "$TMP/spacing0.nrrd: field 'spacings': spacing (1, 0, 1)"});
  c.push_back({"import", "NRRD: gzip encoding of data that is not gzip",
               nrrd("notgz.nrrd", nrrd_head + "sizes: 16 16 16\nencoding: gzip\n"), "brickyard import $TMP/notgz.nrrd --out $TMP/i.store",
               1, "$TMP/notgz.nrrd: field 'encoding': the header says encoding gzip, but the data at byte"});

  // MetaImage: a 16^3 header; ElementType, compression and ElementDataFile follow per case.
  const std::string mha_head = "ObjectType = Image\nNDims = 3\nBinaryData = True\nDimSize = 16 16 16\n";
  c.push_back({"import", "MetaImage: data truncated",
               text("trunc.mha", mha_head + "ElementType = MET_UCHAR\nElementDataFile = LOCAL\n" + std::string(100, '\1')),
               "brickyard import $TMP/trunc.mha --out $TMP/i.store", 1,
               "$TMP/trunc.mha: field 'DimSize': data is truncated: 100 bytes after the header, but DimSize 16x16x16 of "
               "MET_UCHAR needs 4096"});
  c.push_back({"import", "MetaImage: unknown ElementType",
               text("type.mha", mha_head + "ElementType = MET_BLOB\nElementDataFile = LOCAL\n" + std::string(4096, '\1')),
               "brickyard import $TMP/type.mha --out $TMP/i.store", 1,
               "$TMP/type.mha: field 'ElementType': unknown ElementType 'MET_BLOB'"});
  c.push_back({"import", "MetaImage: compressed data that is not zlib",
               text("zbad.mha", mha_head + "CompressedData = True\nElementType = MET_UCHAR\nElementDataFile = LOCAL\n" +
                                    std::string(100, 'x')),
               "brickyard import $TMP/zbad.mha --out $TMP/i.store", 1,
               "$TMP/zbad.mha: field 'CompressedData': the zlib data is corrupt after 0 decompressed bytes: incorrect "
               "header check"});
  c.push_back({"import", "MetaImage: detached data file missing",
               text("nodata.mhd", mha_head + "ElementType = MET_UCHAR\nElementDataFile = nothere.raw\n"),
               "brickyard import $TMP/nodata.mhd --out $TMP/i.store", 1,
               "$TMP/nodata.mhd: field 'ElementDataFile': the data file 'nothere.raw' does not exist"});

  // NIfTI: files nibabel wrote (tests/data/nifti/), or a copy cut short. Where this build has no
  // nifticlib, every NIfTI file is refused alike, so only the option check is a case then.
  c.push_back({"import", "--time-step for a raw file", {}, "brickyard import " + raw16 + " --time-step 1 --out $TMP/i.store", 2,
               "field '--time-step': does not apply to a raw file"});
  // Several files: the time steps of one grid.
  c.push_back({"import", "time steps: a step of another grid",
               sidecar("t2", [](nlohmann::json& j) {
                 j["dims"] = {16, 16, 16};
                 j["spacing"] = {1, 1, 2};
                 j.erase("xxh3_64");
               }),
               "brickyard import $TMP/s.raw $TMP/t2.raw --out $TMP/i.store", 1,
               "$TMP/t2.raw: time step 1 has spacing 1,1,2 and origin 0,0,0, but step 0 ($TMP/s.raw) is 16x16x16 u8 voxels"});
  c.push_back({"import", "time steps: fields", {}, "brickyard import field:sphere field:torus --size 16 --out $TMP/i.store", 2,
               "field:sphere: several sources are the time steps of one grid: volume files only"});
  c.push_back({"import", "time steps: --time-step all with several files", {},
               "brickyard import $SRC/tests/data/nifti/4d.nii $SRC/tests/data/nifti/4d.nii --time-step all --out $TMP/i.store", 2,
               "field '--time-step': takes the time steps of one 4D file"});
  c.push_back({"import", "--time-step not a step", {}, "brickyard import $SRC/tests/data/nifti/4d.nii --time-step 1.5 --out $TMP/i.store",
               2, "field '--time-step': '1.5' is not a time step (0, 1, ... or all)"});
#if BRICKYARD_HAVE_NIFTI
  c.push_back({"import", "NIfTI: data truncated",
               [](const Workspace& ws) {
                 ws.write("trunc.nii", testing::read_file(kSource + "/tests/data/nifti/int16.nii").substr(0, 672));
               },
               "brickyard import $TMP/trunc.nii --out $TMP/i.store", 1,
               "$TMP/trunc.nii: field 'dim': the data is truncated: 320 bytes from byte 352 (vox_offset), but 7x6x5 INT16 "
               "needs 420"});
  c.push_back({"import", "NIfTI: unsupported datatype", {}, "brickyard import $SRC/tests/data/nifti/complex64.nii --out $TMP/i.store", 1,
               "$SRC/tests/data/nifti/complex64.nii: field 'datatype': datatype 32 (COMPLEX64) is not supported"});
  c.push_back({"import", "NIfTI: 4D without --time-step", {}, "brickyard import $SRC/tests/data/nifti/4d.nii --out $TMP/i.store", 2,
               "$SRC/tests/data/nifti/4d.nii: field '--time-step': the file holds 3 time steps (dim[4])"});
#endif

  // DICOM: series pydicom wrote (tests/data/dicom/), or a directory of other files. Without GDCM
  // every DICOM series is refused alike, so the cases need it.
#if BRICKYARD_HAVE_DICOM
  c.push_back({"import", "DICOM: no DICOM files in a directory",
               [](const Workspace& ws) {
                 fs::create_directory(ws.file("notdicom"));
                 ws.write("notdicom/readme.txt", "not a DICOM file\n");
               },
               "brickyard import $TMP/notdicom --out $TMP/i.store", 1,
               "$TMP/notdicom: no DICOM files in this directory: it holds 1 file that is not DICOM (readme.txt)"});
  c.push_back({"import", "DICOM: irregular slice spacing", {}, "brickyard import $SRC/tests/data/dicom/irregular --out $TMP/i.store", 1,
               "$SRC/tests/data/dicom/irregular: field 'ImagePositionPatient': irregular slice spacing: the gap between "
               "irr_2.dcm at (0, 0, 2) and irr_3.dcm at (0, 0, 3.5) is 1.5 mm, the median gap 1 mm"});
  c.push_back({"import", "DICOM: unknown --series", {},
               "brickyard import $SRC/tests/data/dicom/ct --series 1.2.3.4 --out $TMP/i.store", 2,
               "field '--series': no series 1.2.3.4 in $SRC/tests/data/dicom/ct: it holds 1 series: "
               "1.2.826.0.1.3680043.8.498.69023019117229732970297373541128519901 (5 slices, CT)"});
#endif

  // netCDF: files netCDF4-python wrote (tests/data/netcdf/), or text named .nc. Without netCDF-C
  // every netCDF file is refused alike, so the cases need it.
#if BRICKYARD_HAVE_NETCDF
  c.push_back({"import", "netCDF: unknown variable", {},
               "brickyard import $SRC/tests/data/netcdf/ocean.nc --variable TEMP --time-step 0 --out $TMP/i.store", 1,
               "$SRC/tests/data/netcdf/ocean.nc: field '--variable': no variable named 'TEMP'; the file has 'time(time)', "
               "'depth(depth)', 'lat(lat)', 'lon(lon)', 'temp(time, depth, lat, lon)'"});
  c.push_back({"import", "netCDF: 4D without --time-step", {}, "brickyard import $SRC/tests/data/netcdf/ocean.nc --out $TMP/i.store", 2,
               "$SRC/tests/data/netcdf/ocean.nc: field '--time-step': variable 'temp' holds 2 time steps (dimension "
               "'time')"});
  c.push_back({"import", "netCDF: not a netCDF file", text("notes.nc", "these are notes, not data\n"),
               "brickyard import $TMP/notes.nc --out $TMP/i.store", 1,
               "$TMP/notes.nc: not a netCDF file: NetCDF: Unknown file format"});
#endif
}

void add_scene_cases(std::vector<Case>& c) {
  // --- scene: the JSON a render reads
  auto scene_case = [&](const std::string& name, const std::string& file, const std::string& members, int exit_code,
                        const std::string& expect, const std::string& dataset = "grid.store") {
    c.push_back({"scene", name, scene(file, members, dataset), "brickyard -q render $TMP/" + file + " -o $TMP/x.png", exit_code,
                 expect});
  };
  scene_case("unknown key", "typo.json", kCam + ", " + kIso + R"(, "shading": {"ligth": "point"})", 1,
             "$TMP/typo.json: field 'shading.ligth': unknown key");
  scene_case("not valid JSON", "syntax.json", kCam + ", " + kIso + ", \"mode\": ", 1, "$TMP/syntax.json: not valid JSON");
  c.push_back({"scene", "not an object", text("array.json", "[]\n"), "brickyard -q render $TMP/array.json -o $TMP/x.png", 1,
               "$TMP/array.json: field '(top level)': expected an object"});
  scene_case("wrong type", "wtype.json", kCam + ", " + kIso + R"(, "image": {"width": "big", "height": 16})", 1,
             "$TMP/wtype.json: field 'image.width': expected an integer, found a string");
  scene_case("image width zero", "width.json", kCam + ", " + kIso + R"(, "image": {"width": 0, "height": 16})", 1,
             "$TMP/width.json: field 'image.width'");
  scene_case("unknown mode", "mode.json", kCam + R"(, "mode": "volume")", 1, "$TMP/mode.json: field 'mode': 'volume' is not one of");
  scene_case("iso without isosurfaces", "noiso.json", kCam + R"(, "mode": "iso")", 1, "$TMP/noiso.json: field 'isosurfaces'");
  scene_case("five isosurfaces", "iso5.json",
             kCam + R"(, "isosurfaces": [{"value": 0}, {"value": 0.1}, {"value": 0.2}, {"value": 0.3}, {"value": 0.4}])", 1,
             "$TMP/iso5.json: field 'isosurfaces': expected an array of 1 to 4");
  scene_case("dvr without a transfer function", "notf.json", kCam + R"(, "mode": "dvr")", 1,
             "$TMP/notf.json: field 'transfer_function': dvr mode needs a transfer function");
  scene_case("transfer function out of order", "tforder.json",
             kCam + R"(, "mode": "dvr", "transfer_function": {"points": [{"value": 0.5, "color": [1, 1, 1], "opacity": 0.5},)"
                    R"( {"value": 0.1, "color": [1, 1, 1], "opacity": 0.5}]})",
             1, "$TMP/tforder.json: field 'transfer_function.points[1].value': points must be in increasing order");
  scene_case("background colour out of range", "bg.json", kCam + ", " + kIso + R"(, "background": [2, 0, 0])", 1,
             "$TMP/bg.json: field 'background'");
  scene_case("empty clip box", "clip.json", kCam + ", " + kIso + R"(, "clip": {"lo": [0.6, 0, 0], "hi": [0.4, 1, 1]})", 1,
             "$TMP/clip.json: field 'clip.hi': the clip box is empty");
  scene_case("camera and camera_path", "both.json",
             kCam + ", " + kIso + R"(, "camera_path": {"frames": 2, "keyframes": [{"eye": [1.8, -1.2, 1.4], "target": [0.5, 0.5, 0.5]}]})",
             1, "$TMP/both.json: field 'camera_path': give exactly one of 'camera' and 'camera_path'");
  scene_case("no camera", "nocam.json", kIso, 1, "$TMP/nocam.json: field 'camera': give exactly one");
  scene_case("camera eye of two numbers", "eye.json", R"("camera": {"eye": [1.8, -1.2], "target": [0.5, 0.5, 0.5]}, )" + kIso, 1,
             "$TMP/eye.json: field 'camera.eye': expected [x, y, z]");
  scene_case("eye at the target", "eyetarget.json", R"("camera": {"eye": [0.5, 0.5, 0.5], "target": [0.5, 0.5, 0.5]}, )" + kIso, 1,
             "$TMP/eyetarget.json: field 'camera");
  scene_case("camera_path file missing", "cpfile.json", R"("camera_path": "nothere-path.json", )" + kIso, 1, "nothere-path.json");
  scene_case("unknown back end", "backend.json", kCam + ", " + kIso + R"(, "backend": "raytrace")", 1,
             "$TMP/backend.json: field 'backend': unknown back end 'raytrace' (known: 'reference'");
  scene_case("back-end parameter out of range", "param.json",
             kCam + ", " + kIso + R"(, "backend": {"name": "raymarch", "params": {"step": -1}})", 1,
             "$TMP/param.json: field 'backend.params.step': -1 is outside");
  scene_case("fraction for a switch", "exact.json", kCam + ", " + kIso + R"(, "backend": {"name": "gigavoxels", "params": {"exact": 0.5}})",
             1, "$TMP/exact.json: field 'backend.params.exact': 0.5 is not a whole number");
  scene_case("unknown light", "light.json", kCam + ", " + kIso + R"(, "shading": {"light": "spot"})", 1,
             "$TMP/light.json: field 'shading.light': 'spot' is not one of");
  scene_case("directional light of zero length", "dir.json",
             kCam + ", " + kIso + R"(, "shading": {"light": "directional", "light_direction": [0, 0, 0]})", 1,
             "$TMP/dir.json: field 'shading.light_direction': must not be zero");
  scene_case("shadows in dvr mode", "shadow.json", kCam + R"(, "mode": "dvr", )" + kTf + R"(, "shading": {"shadows": true})", 1,
             "$TMP/shadow.json: field 'shading.shadows': shadows are cast in iso mode only");
  scene_case("normals a back end lacks", "gobnormals.json",
             kCam + ", " + kIso + R"(, "backend": "gobbetti", "shading": {"normals": "central"})", 1,
             "$TMP/gobnormals.json: field 'shading.normals': gobbetti does not compute central normals");
  scene_case("mode a back end lacks", "gobmip.json", kCam + R"(, "mode": "mip", "backend": "gobbetti", )" + kTf, 2,
             "$TMP/gobmip.json: field 'mode': back end 'gobbetti' does not render mip mode");
  scene_case("time_step past the last", "ts.json", kCam + ", " + kIso + R"(, "time_step": 1)", 2,
             "$TMP/ts.json: field 'time_step': time step 1 of a dataset with 1");
  scene_case("time_series past the last", "tseries.json", kCam + ", " + kIso + R"(, "time_series": {"first": 0, "count": 3})", 2,
             "$TMP/tseries.json: field 'time_series'");
  scene_case("L1 smaller than a brick", "l1small.json", kCam + ", " + kIso + R"(, "cache": {"l1": 100})", 2,
             "$TMP/l1small.json: field 'cache.l1': the L1 budget of 100 B is smaller than one brick");
  scene_case("L2 of zero", "l2zero.json", kCam + ", " + kIso + R"(, "cache": {"l2": 0})", 2,
             "$TMP/l2zero.json: field 'cache.l2': the L2 budget of 0 B");
  scene_case("gigavoxels L1 below its pool", "gvl1.json", kCam + ", " + kIso + R"(, "backend": "gigavoxels", "cache": {"l1": 30000})",
             2, "$TMP/gvl1.json: field 'cache.l1': gigavoxels needs an L1 of at least");
  scene_case("opt as a live policy", "opt.json", kCam + ", " + kIso + R"(, "cache": {"l1_policy": "opt"})", 1,
             "$TMP/opt.json: field 'cache.l1_policy': 'opt' is not a policy a live cache can run");
  scene_case("dataset missing", "nostore.json", kCam + ", " + kIso, 1, "$TMP/no-such.store: no such store", "no-such.store");
  scene_case("grid for a mesh-only back end", "tetgrid.json", kCam + ", " + kIso + R"(, "backend": "tet_bvh")", 1,
             "$TMP/grid.store: back end 'tet_bvh' does not render structured datasets");
  scene_case("octree_cgt without an octree", "octree.json", kCam + ", " + kIso + R"(, "backend": "octree_cgt")", 1,
             "$TMP/grid.store: the grid has no octree volume; build one with 'brickyard build-octree");
  scene_case("up against the view", "upview.json",
             R"("camera": {"eye": [0.5, 0.5, 2], "target": [0.5, 0.5, 0.5], "up": [0, 0, 1]}, )" + kIso, 1,
             "$TMP/upview.json: field 'camera.up': up (0, 0, 1) points against the viewing direction");
  scene_case("a number too large for a double", "e999.json",
             R"("camera": {"eye": [1.8, -1.2, 1e999], "target": [0.5, 0.5, 0.5]}, )" + kIso, 1,
             "$TMP/e999.json: not valid JSON: number overflow parsing '1e999'");
  c.push_back({"scene", "scene path is a directory", {}, "brickyard -q render $TMP/plain -o $TMP/x.png", 1,
               "$TMP/plain: is a directory, not a file"});
  c.push_back({"scene", "scene file missing", {}, "brickyard -q render $TMP/absent.json -o $TMP/x.png", 1, "$TMP/absent.json"});
}

void add_render_cases(std::vector<Case>& c) {
  // --- render and bench options
  c.push_back({"render", "unknown --backend", {}, render + "--backend raytrace -o $TMP/x.png", 2,
               "field 'backend': unknown back end 'raytrace'"});
  c.push_back({"render", "--set of an undeclared parameter", {}, render + "--set stride=2 -o $TMP/x.png", 2,
               "field 'backend.params.stride': back end 'raymarch' has no parameter 'stride' (its parameters: 'step'"});
  c.push_back({"render", "--frames past the path", {}, render + "--frames 3 -o $TMP/x.png", 2,
               "field '--frames': '3' is outside the scene's frames 0-0"});
  c.push_back({"render", "--frames not a list", {}, render + "--frames abc -o $TMP/x.png", 2, "field '--frames': 'abc'"});
  c.push_back({"render", "--time-step past the dataset's steps", {}, render + "--time-step 2 -o $TMP/x.png", 2,
               "field 'time_step': time step 2 of a dataset with 1 (0 to 0)"});
  c.push_back({"render", "--set time_step not a step", {}, render + "--set time_step=-1 -o $TMP/x.png", 2,
               "field '--set time_step': '-1' is not a time step"});
  c.push_back({"render", "no scene", {}, "brickyard render -o $TMP/x.png", 2, "field 'SCENE': a scene file is required"});
  c.push_back({"render", "no -o", {}, render, 2, "field '-o': an output PNG is required"});
  c.push_back({"render", "-o is a directory", {}, render + "-o $TMP/plain", 1,
               "$TMP/plain: exists and is a directory: outputs replace only regular files"});
  c.push_back({"render", "-o is a FIFO", [](const Workspace& ws) { ASSERT_EQ(::mkfifo(ws.file("pipe").c_str(), 0600), 0); },
               render + "-o $TMP/pipe", 1, "$TMP/pipe: exists and is a FIFO"});
  c.push_back({"render", "--error-maps is a file", {}, render + "-o $TMP/x.png --error-maps $TMP/afile", 2,
               "$TMP/afile: field '--error-maps': exists and is not a directory"});
  c.push_back({"render", "-o not a PNG name", {}, render + "-o $TMP/x.jpg", 2,
               "$TMP/x.jpg: field '-o': images are written as PNG: give the file a .png name"});
  c.push_back({"render", "--frames that run backwards", {}, render + "--frames 2-1 -o $TMP/x.png", 2,
               "field '--frames': '2-1' runs backwards"});
  c.push_back({"render", "bench --out is a file", {}, bench + "--out $TMP/afile", 2,
               "$TMP/afile: field '--out': exists and is not a directory"});
  c.push_back({"render", "bench --frame past the path", {}, bench + "--frame 99", 2,
               "field '--frame': '99' is outside the scene's frames 0-0"});
  c.push_back({"render", "bench --quality not a number", {}, bench + "--quality step=abc", 2,
               "field '--quality': 'abc' in 'step=abc' is not a finite number"});
  c.push_back({"render", "bench --backends unknown", {}, "brickyard -q bench $TMP/ok.json --backends bogus --warm 1 --cold 0", 2,
               "field '--backends': unknown back end 'bogus'"});
  c.push_back({"render", "image larger than the free memory",
               scene("huge.json", kCam + ", " + kIso + R"(, "image": {"width": 16384, "height": 16384})"),
               "BRICKYARD_AVAILABLE_MEMORY=1GiB brickyard render $TMP/huge.json -o $TMP/x.png", 4,
               "render of 16384x16384 pixels needs about 9.25 GiB of memory"});
  c.push_back({"render", "damaged brick",
               [](const Workspace& ws) {
                 copy_store("grid.store", "damaged.store", damage_facing_brick)(ws);
                 scene("damaged.json", kCam + ", " + kIso + R"(, "quality": {"lod_ratio": 0.01})", "damaged.store")(ws);
               },
               "brickyard -q render $TMP/damaged.json -o $TMP/x.png", 3,
               "$TMP/damaged.store: key " + kFacingBrick.to_string() + ": checksum mismatch"});
  c.push_back({"render", "bench --quality of an unknown knob", {}, bench + "--quality stepp=1 --out $TMP/b", 2,
               "field '--quality': no back end benchmarked here has a parameter 'stepp'"});
  c.push_back({"render", "bench --quality without values", {}, bench + "--quality step --out $TMP/b", 2,
               "field '--quality': 'step' is not NAME=V1,V2,..."});
  c.push_back({"render", "bench --peers with an empty list of steady times",
               text("peers.json", R"({"peers": [{"name": "vtk", "first_frame_s": 0.5, "steady_s": [], "image": "v.png"}]})"),
               bench + "--peers $TMP/peers.json --out $TMP/b", 1, "$TMP/peers.json: field 'peers[0].steady_s'"});
  c.push_back({"render", "bench --peers image missing",
               text("peers2.json", R"({"peers": [{"name": "vtk", "first_frame_s": 0.5, "steady_s": [0.1], "image": "none.png"}]})"),
               bench + "--peers $TMP/peers2.json --out $TMP/b", 1, "$TMP/none.png: no such image"});
  c.push_back({"render", "bench --reference-supersample even", {}, bench + "--reference-supersample 2 --out $TMP/b", 2,
               "field '--reference-supersample': 2 must be odd"});
  c.push_back({"render", "bench --reference-supersample too large", {}, bench + "--reference-supersample 1025 --out $TMP/b", 2,
               "field '--reference-supersample'"});
  c.push_back({"render", "bench --size of zero", {}, bench + "--size 0,0 --out $TMP/b", 2,
               "field '--size': image size must be in 1..16384"});
  c.push_back({"render", "bench --size of one number", {}, bench + "--size 16 --out $TMP/b", 2,
               "field '--size': '16' has 1 numbers; give 2"});
  c.push_back({"render", "bench larger than the free memory", {},
               "BRICKYARD_AVAILABLE_MEMORY=1GiB brickyard -q bench $TMP/ok.json --backends raymarch --size 16384,16384 --out $TMP/b", 4,
               "bench at 16384x16384 pixels needs about"});
}

void add_store_cases(std::vector<Case>& c) {
  // --- store: info, verify, export, build-octree
  c.push_back({"store", "a directory that is not a store", {}, "brickyard info $TMP/plain", 1,
               "$TMP/plain: not a brickyard store (no data.mdb)"});
  c.push_back({"store", "a file that is not a store", {}, "brickyard info $TMP/afile", 1,
               "$TMP/afile: not a brickyard store (not a directory)"});
  c.push_back({"store", "no such store", {}, "brickyard verify $TMP/missing.store", 1, "$TMP/missing.store: no such store"});
  c.push_back({"store", "export: a time step the store does not have", {},
               "brickyard export $TMP/grid.store --time-step 1 --out $TMP/x.raw", 2,
               "$TMP/grid.store: field '--time-step': time step 1 of a store with 1 (0 to 0)"});
  c.push_back({"store", "export: --time-step of a mesh", {}, "brickyard export $TMP/mesh.store --time-step 0 --out $TMP/x.vtu", 2,
               "field '--time-step': a mesh exports whole, every time step in its .vtu"});
  c.push_back({"store", "data.mdb that is not LMDB",
               [](const Workspace& ws) {
                 fs::create_directory(ws.file("junk.store"));
                 ws.write("junk.store/data.mdb", "hello\n");
               },
               "brickyard info $TMP/junk.store", 1, "$TMP/junk.store: mdb_env_open failed"});
  c.push_back({"store", "newer format version",
               copy_store("grid.store", "v99.store", [](const std::string& s) { set_format_version(s, 99); }),
               "brickyard info $TMP/v99.store", 1, "store format version 99 is newer than this build reads"});
  c.push_back({"store", "manifest fails its checksum",
               copy_store("grid.store", "manifest.store",
                          [](const std::string& s) { testing::flip_record_bit(s, kManifestDb, bytes_of("manifest"), 123); }),
               "brickyard info $TMP/manifest.store", 1, "$TMP/manifest.store: key manifest: the manifest fails its checksum"});
  c.push_back({"store", "node table fails its checksum",
               copy_store("grid.store", "nodes.store",
                          [](const std::string& s) {
                            testing::flip_record_bit(s, kNodesDb, testing::big_endian_key(uint64_t(1) << 32), 123);  // level 1, chunk 0
                          }),
               "brickyard verify $TMP/nodes.store", 1, "node table chunk 0 of level 1 fails its checksum"});
  c.push_back({"store", "octree page table fails its checksum",
               copy_store("octree.store", "octtable.store",
                          [](const std::string& s) {
                            testing::flip_record_bit(s, kOctreeDb, testing::big_endian_key(uint64_t(0xff) << 56), 123);
                          }),
               "brickyard verify $TMP/octtable.store", 1, "octree page table chunk 0 fails its checksum"});
  c.push_back({"store", "brick fails its checksum",
               copy_store("grid.store", "brick.store", damage_facing_brick),
               "brickyard verify $TMP/brick.store", 1, kFacingBrick.to_string()});
  c.push_back({"store", "brick record missing",
               copy_store("grid.store", "nobrick.store",
                          [](const std::string& s) { erase_record(s, kBricksDb, testing::big_endian_key(kFacingBrick.code())); }),
               "brickyard verify $TMP/nobrick.store", 1, kFacingBrick.to_string()});
  c.push_back({"store", "verify an interrupted build", interrupted_store("cut.store"), "brickyard verify $TMP/cut.store", 1,
               "INCOMPLETE (build interrupted)"});
  c.push_back({"store", "export an interrupted build", interrupted_store("cut2.store"),
               "brickyard export $TMP/cut2.store --out $TMP/x.raw", 1, "the store is incomplete"});
  c.push_back({"store", "export --level past the coarsest", {}, "brickyard export $TMP/grid.store --level 7 --out $TMP/x.raw", 2,
               "field '--level': level 7 does not exist (the store has levels 0 to 1)"});
  c.push_back({"store", "export --box of four numbers", {}, "brickyard export $TMP/grid.store --box 0,0,0,8 --out $TMP/x.raw", 2,
               "field '--box': '0,0,0,8' has 4 numbers; give 6"});
  c.push_back({"store", "export --box not integers", {}, "brickyard export $TMP/grid.store --box a,b,c,d,e,f --out $TMP/x.raw", 2,
               "field '--box': 'a,b,c,d,e,f' is not 6 integers"});
  c.push_back({"store", "export --box outside the level", {},
               "brickyard export $TMP/grid.store --box 0,0,0,40,40,40 --out $TMP/x.raw", 2, "field '--box'"});
  c.push_back({"store", "export into a missing directory", {}, "brickyard export $TMP/grid.store --out $TMP/nodir/x.raw", 1,
               "$TMP/nodir/x.raw: its directory $TMP/nodir does not exist"});
  c.push_back({"store", "export --encoding of a grid", {}, "brickyard export $TMP/grid.store --encoding zlib --out $TMP/x.raw", 2,
               "field '--encoding': --encoding applies to .vtu export of meshes"});
  c.push_back({"store", "build-octree --tolerance below zero", {}, "brickyard build-octree $TMP/grid.store --tolerance -1", 2,
               "field '--tolerance': tolerance -1 is below zero"});

  c.push_back({"store", "info on an interrupted build", interrupted_store("cut3.store"), "brickyard info $TMP/cut3.store", 1,
               "$TMP/cut3.store: the store is incomplete (build interrupted): run the import again to finish it"});
  c.push_back({"store", "info on a store being built",
               [](const Workspace& ws) {
                 interrupted_store("live.store")(ws);
                 ws.hold(std::make_shared<StoreWriteLock>(ws.file("live.store")));
               },
               "brickyard info $TMP/live.store", 1,
               "the store is incomplete (being built by process $PID): it cannot be used until that build finishes"});
  c.push_back({"store", "export --level -1", {}, "brickyard export $TMP/grid.store --level -1 --out $TMP/x.raw", 2,
               "field '--level': level -1 does not exist (the store has levels 0 to 1)"});
  c.push_back({"store", "export a grid under an image's name", {}, "brickyard export $TMP/grid.store --out $TMP/x.png", 2,
               "$TMP/x.png: field '--out': a grid exports to raw bytes (.raw, .bin or .dat, with a .json sidecar beside it) or "
               "to .vdb; '.png' is neither"});
}

void add_cache_cases(std::vector<Case>& c) {
  // --- cache: flight
  c.push_back({"cache", "--l1 with an unknown unit", {}, flight + "--l1 12XB", 2, "field '--l1': '12XB' is not a size"});
  c.push_back({"cache", "unknown --l1-policy", {}, flight + "--l1-policy mru", 2, "unknown cache policy 'mru' (known policies: lru"});
  c.push_back({"cache", "opt as a live --l2-policy", {}, flight + "--l2-policy opt", 2, "policy 'opt' needs future accesses"});
  c.push_back({"cache", "--loaders zero", {}, flight + "--loaders 0", 2, "0 loader threads"});
  c.push_back({"cache", "--lod zero", {}, flight + "--lod 0", 2, "'--lod'"});
  c.push_back({"cache", "--frames zero", {}, flight + "--frames 0", 2, "'--frames'"});
  c.push_back({"cache", "--values over a grid", {}, flight + "--values 0,1", 2, "$TMP/grid.store: --values applies to meshes"});
  c.push_back({"cache", "--time-step past a grid's steps", {}, flight + "--time-step 1", 2,
               "field '--time-step': time step 1 of a grid with 1"});
  c.push_back({"cache", "--path missing", {}, "brickyard flight $TMP/grid.store --path $TMP/nothere.json", 1,
               "$TMP/nothere.json: cannot open"});
  c.push_back({"cache", "path without keyframes", text("nokeys.json", R"({"frames": 2, "camera_path": {"keyframes": []}})"),
               "brickyard flight $TMP/grid.store --path $TMP/nokeys.json", 1,
               "$TMP/nokeys.json: field 'camera_path.keyframes': expected a non-empty array of cameras"});
  c.push_back({"cache", "path with an unknown key",
               text("pathkey.json", R"({"frames": 2, "colour": 1, "camera_path": {"keyframes": [)"
                                    R"({"eye": [0.5, -1.5, 0.5], "target": [0.5, 0.5, 0.5]}]}})"),
               "brickyard flight $TMP/grid.store --path $TMP/pathkey.json", 1, "$TMP/pathkey.json: field 'colour': unknown key"});
  c.push_back({"cache", "--trace under a regular file", {}, flight + "--trace $TMP/afile/f.bytrace", 1, "$TMP/afile/f.bytrace"});
  c.push_back({"cache", "damaged brick", copy_store("grid.store", "fdamaged.store", damage_facing_brick),
               "brickyard -q flight $TMP/fdamaged.store --path $TMP/path.json --lod 0.01", 3,
               "$TMP/fdamaged.store: key " + kFacingBrick.to_string() + ": checksum mismatch"});

  c.push_back({"cache", "--l1 larger than the free memory", {}, "BRICKYARD_AVAILABLE_MEMORY=1GiB " + flight + "--l1 4GiB", 4,
               "flight with an L1 pool of 4 GiB needs"});
  c.push_back({"cache", "--l1 below one brick", {}, flight + "--l1 1", 2, "field '--l1': the L1 budget of 1 B is smaller than one brick"});
}

void add_trace_cases(std::vector<Case>& c) {
  // --- trace: cachebench
  c.push_back({"trace", "no BYTRACE1 magic", trace_with_byte("magic.bytrace", 0, 'X'), "brickyard cachebench $TMP/magic.bytrace", 1,
               "$TMP/magic.bytrace: not a brickyard trace (no BYTRACE1 magic)"});
  c.push_back({"trace", "header only, cut short", text("head.bytrace", "BYTRACE1"), "brickyard cachebench $TMP/head.bytrace", 1,
               "$TMP/head.bytrace"});
  c.push_back({"trace", "truncated records",
               [](const Workspace& ws) { ws.write("trunc.bytrace", ws.read("good.bytrace").substr(0, 16 + 24 * 10 + 7)); },
               "brickyard cachebench $TMP/trunc.bytrace", 1, "$TMP/trunc.bytrace: header says 200 records"});
  c.push_back({"trace", "unknown access kind", trace_with_byte("kind.bytrace", 16 + 24 * 3 + 16, 9),
               "brickyard cachebench $TMP/kind.bytrace", 1, "$TMP/kind.bytrace: record 3: unknown access kind 9"});
  c.push_back({"trace", "unknown record kind", trace_with_byte("rkind.bytrace", 16 + 24 * 4 + 18, 77),
               "brickyard cachebench $TMP/rkind.bytrace", 1, "$TMP/rkind.bytrace: record 4: unknown record kind 77"});
  c.push_back({"trace", "oracleGeneral of part records", text("odd.oracleGeneral", std::string(30, '\0')),
               "brickyard cachebench $TMP/odd.oracleGeneral", 1,
               "$TMP/odd.oracleGeneral: 30 bytes is not a whole number of 24-byte oracleGeneral records"});
  c.push_back({"trace", "text line not integers", text("bad.txt", "1 2\nxyz\n"), "brickyard cachebench $TMP/bad.txt", 1,
               "$TMP/bad.txt: line 2: expected 'key [size [kind]]' with integers"});
  c.push_back({"trace", "text record kind unknown", text("kindname.txt", "1 64 voxel\n"), "brickyard cachebench $TMP/kindname.txt", 1,
               "$TMP/kindname.txt: line 1: unknown record kind 'voxel'"});
  c.push_back({"trace", "text line with a fourth word", text("extra.txt", "1 64 brick more\n"), "brickyard cachebench $TMP/extra.txt", 1,
               "$TMP/extra.txt: line 1: unexpected 'more'"});
  c.push_back({"trace", "no demand accesses", text("empty.txt", "# nothing\n"), "brickyard cachebench $TMP/empty.txt", 2,
               "$TMP/empty.txt: the trace has no demand accesses to replay"});
  c.push_back({"trace", "trace file missing", {}, "brickyard cachebench $TMP/nothere.bytrace", 1, "$TMP/nothere.bytrace: cannot open"});
  c.push_back({"trace", "unknown --format", {}, cachebench + "--format bogus", 2, "unknown trace format 'bogus'"});
  c.push_back({"trace", "--sizes of 0%", {}, "brickyard cachebench $TMP/good.bytrace --sizes 0%", 2, "--sizes"});
  c.push_back({"trace", "neither a trace nor --synthetic", {}, "brickyard cachebench", 2, "give a TRACE file or --synthetic"});
  c.push_back({"trace", "unknown synthetic trace", {}, "brickyard cachebench --synthetic spiral", 2, "unknown synthetic trace 'spiral'"});
  c.push_back({"trace", "unknown synthetic parameter", {}, "brickyard cachebench --synthetic zipf:objectz=5", 2,
               "field '--synthetic': 'objectz' is not a parameter"});
  c.push_back({"trace", "synthetic of zero objects", {}, "brickyard cachebench --synthetic zipf:objects=0", 2,
               "field '--synthetic': objects and size must be positive"});
  c.push_back({"trace", "synthetic larger than the free memory", {},
               "BRICKYARD_AVAILABLE_MEMORY=1GiB brickyard cachebench --synthetic zipf:objects=1000,requests=1e12", 4,
               "cachebench --synthetic zipf:objects=1000,requests=1e12 needs about"});

  c.push_back({"trace", "text key with a sign", text("neg.txt", "-5 64\n"), "brickyard cachebench $TMP/neg.txt", 1,
               "$TMP/neg.txt: line 1: expected 'key [size [kind]]' with integers, got '-5 64'"});
  c.push_back({"trace", "unknown --to", {}, cachebench + "--convert $TMP/o.txt --to bogus", 2,
               "field '--to': unknown trace format 'bogus'"});
  c.push_back({"trace", "trace path is a directory", {}, "brickyard cachebench $TMP/plain", 1, "$TMP/plain: is a directory, not a file"});
}

void add_mesh_cases(std::vector<Case>& c) {
  // --- mesh: tetrahedral meshes
  const std::string tet4 = "4 3 0 0\n0 0 0 0\n1 1 0 0\n2 0 1 0\n3 0 0 1\n";  // a .node file of four vertices
  c.push_back({"mesh", "truncated .vtu",
               [](const Workspace& ws) {
                 const std::string good = testing::read_file(kSource + "/tests/data/mesh/hex_ascii.vtu");
                 ws.write("truncated.vtu", good.substr(0, good.size() / 2));
               },
               "brickyard -q import $TMP/truncated.vtu -o $TMP/m.store", 1, "$TMP/truncated.vtu"});
  c.push_back({"mesh", "VTK XML that is not an UnstructuredGrid", text("poly.vtu", R"(<VTKFile type="PolyData"></VTKFile>)"),
               "brickyard -q import $TMP/poly.vtu -o $TMP/m.store", 1, "$TMP/poly.vtu: is a VTK XML PolyData file"});
  c.push_back({"mesh", "legacy VTK without its header", text("bad.vtk", "not a vtk file\n"),
               "brickyard -q import $TMP/bad.vtk -o $TMP/m.store", 1, "$TMP/bad.vtk: line 1: not a legacy VTK file"});
  c.push_back({"mesh", "legacy VTK CELLS count wrong",
               text("cells.vtk", "# vtk DataFile Version 3.0\nx\nASCII\nDATASET UNSTRUCTURED_GRID\nPOINTS 4 float\n"
                                 "0 0 0 1 0 0 0 1 0 0 0 1\nCELLS 2 5\n4 0 1 2 3\nCELL_TYPES 1\n10\n"),
               "brickyard -q import $TMP/cells.vtk -o $TMP/m.store", 1, "$TMP/cells.vtk: line 8: CELLS says 2 cells"});
  c.push_back({"mesh", "legacy VTK of polygons",
               text("poly.vtk", "# vtk DataFile Version 3.0\nx\nASCII\nDATASET POLYDATA\nPOINTS 4 float\n0 0 0 1 0 0 0 1 0 0 0 1\n"),
               "brickyard -q import $TMP/poly.vtk -o $TMP/m.store", 1, "$TMP/poly.vtk: dataset POLYDATA"});
  c.push_back({"mesh", "MSH of an unknown version", text("bad.msh", "$MeshFormat\n9.9 0 8\n$EndMeshFormat\n"),
               "brickyard -q import $TMP/bad.msh -o $TMP/m.store", 1, "$TMP/bad.msh: MSH version 9.9 is not read"});
  c.push_back({"mesh", "MSH section never ends",
               [](const Workspace& ws) {
                 ws.write("cut.msh", testing::read_file(kSource + "/tests/data/mesh/box_msh41_bin.msh").substr(0, 300));
               },
               "brickyard -q import $TMP/cut.msh -o $TMP/m.store", 1, "$TMP/cut.msh: line 5"});
  c.push_back({"mesh", ".pvd naming a missing file",
               text("steps.pvd", "<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\"><Collection>"
                                 "<DataSet timestep=\"0\" file=\"nothere.vtu\"/></Collection></VTKFile>\n"),
               "brickyard -q import $TMP/steps.pvd -o $TMP/m.store", 1, "nothere.vtu: cannot open"});
  c.push_back({"mesh", ".node without its .ele", text("lone.node", tet4), "brickyard -q import $TMP/lone.node -o $TMP/m.store", 1,
               "$TMP/lone.ele: cannot open"});
  c.push_back({"mesh", ".node of fewer points than it says",
               [](const Workspace& ws) {
                 ws.write("few.node", "4 3 0 0\n0 0 0 0\n1 1 0 0\n2 0 1 0\n");
                 ws.write("few.ele", "1 4 0\n0 0 1 2 3\n");
               },
               "brickyard -q import $TMP/few.node -o $TMP/m.store", 1, "$TMP/few.node: line 1: the number of points says 4"});
  c.push_back({"mesh", ".ele cut short",
               [tet4](const Workspace& ws) {
                 ws.write("short.node", tet4);
                 ws.write("short.ele", "1 4 0\n0 0 1 2\n");
               },
               "brickyard -q import $TMP/short.node -o $TMP/m.store", 1, "$TMP/short.ele: line 3"});
  c.push_back({"mesh", "only degenerate tetrahedra",
               [](const Workspace& ws) {
                 ws.write("flat.node", "4 3 0 0\n0 0 0 0\n1 1 0 0\n2 2 0 0\n3 3 0 0\n");
                 ws.write("flat.ele", "1 4 0\n0 0 1 2 3\n");
               },
               "brickyard -q import $TMP/flat.node -o $TMP/m.store", 1, "$TMP/flat.node: no valid tetrahedron is left"});
  c.push_back({"mesh", "only out-of-range vertex indices",
               [tet4](const Workspace& ws) {
                 ws.write("range.node", tet4);
                 ws.write("range.ele", "1 4 0\n0 0 1 2 9\n");
               },
               "brickyard -q import $TMP/range.node -o $TMP/m.store", 1, "vertex index out of range (cells 0)"});
  c.push_back({"mesh", "--array not in the file", {},
               "brickyard -q import $SRC/tests/data/mesh/hex_ascii.vtu --array nope -o $TMP/m.store", 1,
               "$SRC/tests/data/mesh/hex_ascii.vtu: field '--array': no point array 'nope' (arrays: temperature, id)"});
  c.push_back({"mesh", "a grid build option for a mesh", {}, "brickyard -q import mesh:sphere --brick-size 16 -o $TMP/m.store", 2,
               "field '--brick-size': does not apply to a mesh:FIELD source (mesh:sphere), and would be ignored"});
  c.push_back({"mesh", "--move without --steps", {}, "brickyard -q import mesh:sphere --move 0.5 -o $TMP/m.store", 2,
               "field '--move': moves the vertices from one time step to the next: give --steps 2 or more"});
  c.push_back({"mesh", "a raw option for a mesh file", {}, "brickyard -q import $SRC/tests/data/mesh/hex_ascii.vtu --dims 4 -o $TMP/m.store",
               2, "field '--dims': does not apply to a mesh file"});
  c.push_back({"mesh", "--cells zero", {}, "brickyard -q import mesh:sphere --cells 0 -o $TMP/m.store", 2, "field '--cells'"});
  c.push_back({"mesh", "--jitter past 0.2", {}, "brickyard -q import mesh:sphere --jitter 0.5 -o $TMP/m.store", 2,
               "field '--jitter': jitter 0.5"});
  c.push_back({"mesh", "--cluster-tets below 64", {}, "brickyard -q import mesh:sphere --cells 4 --cluster-tets 0 -o $TMP/m.store", 2,
               "field '--cluster-tets'"});
  c.push_back({"mesh", "export --encoding unknown", {}, "brickyard export $TMP/mesh.store --encoding bogus -o $TMP/x.vtu", 2,
               "field '--encoding': 'bogus' is not ascii, binary"});
  c.push_back({"mesh", "export to a .raw", {}, "brickyard export $TMP/mesh.store -o $TMP/x.raw", 2,
               "$TMP/x.raw: field '--out': a tetrahedral store exports to a .vtu file"});
  c.push_back({"mesh", "export --level", {}, "brickyard export $TMP/mesh.store --level 1 -o $TMP/x.vtu", 2,
               "$TMP/mesh.store: --level, --box and --grid apply to grids"});
  c.push_back({"mesh", "build-octree of a mesh", {}, "brickyard build-octree $TMP/mesh.store", 1,
               "$TMP/mesh.store: an octree volume is built over a grid"});
  c.push_back({"mesh", "flight --time-step past the last", {},
               "brickyard flight $TMP/mesh.store --path $TMP/path.json --time-step 3", 2,
               "field '--time-step': time step 3 of a mesh with 1"});
  c.push_back({"mesh", "grid-only back end", scene("meshscene.json", kCam + ", " + kIso, "mesh.store"),
               "brickyard -q render $TMP/meshscene.json -o $TMP/x.png", 1,
               "$TMP/mesh.store: back end 'raymarch' does not render tetrahedral datasets"});
  c.push_back({"mesh", "cluster fails its checksum",
               copy_store("mesh.store", "cluster.store", [](const std::string& s) { testing::damage_record(s, kTetsDb, 0); }),
               "brickyard verify $TMP/cluster.store", 1, "cluster 0"});
}

}  // namespace

void build_fixtures(const Workspace& ws) {
  auto run = [&](const std::string& args) {
    const auto r = testing::run_command(kExe + " -q " + ws.real(args));
    ASSERT_EQ(r.exit_code, 0) << args << "\n" << r.output;
  };
  ASSERT_NO_FATAL_FAILURE(run("import field:sphere --size 32 --type f32 --brick-size 16 --out $TMP/grid.store"));
  ASSERT_NO_FATAL_FAILURE(run("import field:sphere --size 32 --type f32 --brick-size 16 --octree --out $TMP/octree.store"));
  ASSERT_NO_FATAL_FAILURE(run("import mesh:sphere --cells 4 --cluster-tets 64 -o $TMP/mesh.store"));
  ASSERT_NO_FATAL_FAILURE(run("generate sphere --size 16 --type u8 --out $TMP/s.raw"));
  ASSERT_NO_FATAL_FAILURE(run("cachebench --synthetic zipf:objects=50,requests=200 --convert $TMP/good.bytrace"));
  ws.write("path.json", R"({"frames": 2, "image": {"width": 64, "height": 48},
  "camera_path": {"keyframes": [{"eye": [0.5, -1.5, 0.5], "target": [0.5, 0.5, 0.5]},
                                {"eye": [0.5, 0.2, 0.5], "target": [0.5, 0.9, 0.5]}]}})");
  scene("ok.json", kCam + ", " + kIso)(ws);
  fs::create_directory(ws.file("plain"));
  ws.write("afile", "x\n");
}

std::vector<Case> census_cases() {
  std::vector<Case> c;
  for (auto* add : {add_cli_cases, add_import_cases, add_nrrd_and_vdb_cases, add_scene_cases, add_render_cases, add_store_cases, add_cache_cases,
                    add_trace_cases, add_mesh_cases})
    add(c);
  for (Case& one : c)
    while (!one.command.empty() && one.command.back() == ' ') one.command.pop_back();
  return c;
}

}  // namespace brickyard::census
