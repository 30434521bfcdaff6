// The C API (libfiligree.so, include/filigree/filigree.h): what the library
// exports, its error paths (handles, buffers, server refusals), and a real
// round trip against filigree-server checked against the C++ client's
// decoding of the same frame.
//
// The C++ client cannot be linked into this process: libfiligree.so carries
// its own copy of the generated filigree.proto code, and protobuf aborts when
// one process registers that file twice. The reference decoding therefore
// comes from another process, `filigree watch` (Client + FrameDecoder).

#include <dlfcn.h>
#include <elf.h>
#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <condition_variable>
#include <cstring>
#include <filesystem>
#include <functional>
#include <limits>
#include <mutex>
#include <numbers>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "filigree/filigree.h"
#include "mesh/gltf_io.h"
#include "mesh/mesh_validation.h"
#include "skinning/auto_rig.h"
#include "support/server_process.h"
#include "support/test_meshes.h"

namespace {

using Clock = std::chrono::steady_clock;

std::string last_error() { return filigree_last_error(); }

// Every function filigree.h declares.
const std::set<std::string> kApi = {
    "filigree_status_name", "filigree_version_string", "filigree_last_error", "filigree_connect",
    "filigree_client_set_decode_threads", "filigree_client_set_api_key", "filigree_client_last_error", "filigree_client_free",
    "filigree_create_session", "filigree_join", "filigree_session_id", "filigree_session_editor_token",
    "filigree_session_viewer_token", "filigree_session_vertex_count", "filigree_session_base_vertex_count",
    "filigree_session_rest_positions", "filigree_session_rest_faces", "filigree_session_uploaded_ids",
    "filigree_session_base_positions", "filigree_session_base_faces", "filigree_session_base_original_ids",
    "filigree_session_joint_count", "filigree_session_joint_name", "filigree_session_joint_parent",
    "filigree_session_joint_rest", "filigree_session_clip_count", "filigree_session_clip_name",
    "filigree_session_clip_duration", "filigree_set_handles", "filigree_set_threshold", "filigree_close_session", "filigree_session_last_error",
    "filigree_session_free", "filigree_driver_open", "filigree_driver_send_positions",
    "filigree_driver_send_partial", "filigree_driver_send_joints", "filigree_driver_poll",
    "filigree_driver_frame_info", "filigree_driver_wait_frame", "filigree_driver_wait_for_pose", "filigree_driver_reconnects", "filigree_driver_changes", "filigree_driver_close", "filigree_driver_last_error", "filigree_driver_free",
    "filigree_watcher_open", "filigree_watcher_open_with", "filigree_play_clip", "filigree_play_clip_with", "filigree_watcher_poll",
    "filigree_watcher_level_vertex_count", "filigree_watcher_level_original_ids", "filigree_watcher_level_faces",
    "filigree_watcher_set_detail",
    "filigree_watcher_frame_info", "filigree_watcher_clip_seconds", "filigree_watcher_wait_frame", "filigree_watcher_reconnects", "filigree_watcher_changes", "filigree_watcher_wait", "filigree_watcher_close", "filigree_watcher_last_error", "filigree_watcher_free",
    "filigree_set_handles_in_gesture", "filigree_driver_set_gesture", "filigree_undo", "filigree_redo",
    "filigree_session_edit_message", "filigree_session_edit_conflicts", "filigree_create_checkpoint",
    "filigree_restore_checkpoint", "filigree_diff_checkpoint", "filigree_history_read", "filigree_history_info_get",
    "filigree_history_entry_get", "filigree_history_entry_author", "filigree_history_entry_vertices",
    "filigree_history_checkpoint_get", "filigree_history_checkpoint_name", "filigree_history_checkpoint_author",
    "filigree_history_last_error", "filigree_history_free", "filigree_presence_open", "filigree_presence_poll",
    "filigree_presence_wait", "filigree_presence_participant_count", "filigree_presence_participant_get",
    "filigree_presence_participant_name", "filigree_presence_participant_touching",
    "filigree_presence_participant_handles", "filigree_presence_close", "filigree_presence_last_error",
    "filigree_presence_free", "filigree_set_presence", "filigree_export_history", "filigree_history_export_next",
    "filigree_history_export_author", "filigree_history_export_base_pose", "filigree_history_export_close",
    "filigree_history_export_last_error", "filigree_history_export_free"};

// The names of the symbols the ELF file defines in its dynamic symbol table
// (what dlsym can find), read with <elf.h>.
std::vector<std::string> defined_dynamic_symbols(const std::string& path) {
  const int fd = ::open(path.c_str(), O_RDONLY);
  if (fd < 0) throw std::runtime_error("cannot open " + path);
  struct stat st {};
  ::fstat(fd, &st);
  const std::size_t size = static_cast<std::size_t>(st.st_size);
  void* map = ::mmap(nullptr, size, PROT_READ, MAP_PRIVATE, fd, 0);
  ::close(fd);
  if (map == MAP_FAILED) throw std::runtime_error("cannot map " + path);
  const auto* bytes = static_cast<const unsigned char*>(map);
  std::vector<std::string> names;
  const auto* eh = reinterpret_cast<const Elf64_Ehdr*>(bytes);
  if (std::memcmp(eh->e_ident, ELFMAG, SELFMAG) != 0 || eh->e_ident[EI_CLASS] != ELFCLASS64) {
    ::munmap(map, size);
    throw std::runtime_error(path + " is not a 64-bit ELF file");
  }
  const auto* sections = reinterpret_cast<const Elf64_Shdr*>(bytes + eh->e_shoff);
  for (int s = 0; s < eh->e_shnum; ++s) {
    if (sections[s].sh_type != SHT_DYNSYM) continue;
    const Elf64_Shdr& strtab = sections[sections[s].sh_link];
    const auto* symbols = reinterpret_cast<const Elf64_Sym*>(bytes + sections[s].sh_offset);
    const std::size_t count = sections[s].sh_size / sizeof(Elf64_Sym);
    for (std::size_t i = 0; i < count; ++i) {
      const Elf64_Sym& sym = symbols[i];
      if (sym.st_shndx == SHN_UNDEF || ELF64_ST_BIND(sym.st_info) == STB_LOCAL || sym.st_name == 0) continue;
      names.emplace_back(reinterpret_cast<const char*>(bytes + strtab.sh_offset + sym.st_name));
    }
  }
  ::munmap(map, size);
  return names;
}

TEST(CApiLibrary, ExportsTheCApiAndNothingElse) {
  const std::vector<std::string> names = defined_dynamic_symbols(FILIGREE_C_LIBRARY);
  ASSERT_FALSE(names.empty());
  for (const std::string& name : names) EXPECT_EQ(name.rfind("filigree_", 0), 0u) << "exported: " << name;
  EXPECT_EQ(std::set<std::string>(names.begin(), names.end()), kApi);

  // dlsym finds the API (the very functions this test links) and nothing of
  // the C++ client inside.
  void* lib = dlopen(FILIGREE_C_LIBRARY, RTLD_NOW);
  ASSERT_NE(lib, nullptr) << dlerror();
  EXPECT_EQ(dlsym(lib, "filigree_connect"), reinterpret_cast<void*>(&filigree_connect));
  EXPECT_EQ(dlsym(lib, "filigree_driver_poll"), reinterpret_cast<void*>(&filigree_driver_poll));
  EXPECT_EQ(dlsym(lib, "filigree_last_error"), reinterpret_cast<void*>(&filigree_last_error));
  EXPECT_EQ(dlsym(lib, "filigree_play_clip"), reinterpret_cast<void*>(&filigree_play_clip));
  EXPECT_EQ(dlsym(lib, "_ZN8filigree16status_code_nameEN4grpc10StatusCodeE"), nullptr);  // filigree::status_code_name
  dlclose(lib);
}

TEST(CApiLibrary, VersionAndStatusNames) {
  const std::string version = filigree_version_string();
  EXPECT_EQ(std::count(version.begin(), version.end(), '.'), 2) << version;
  EXPECT_STREQ(filigree_status_name(FILIGREE_OK), "OK");
  EXPECT_STREQ(filigree_status_name(FILIGREE_NOT_FOUND), "NOT_FOUND");
  EXPECT_STREQ(filigree_status_name(16), "UNAUTHENTICATED");
  EXPECT_STREQ(filigree_status_name(FILIGREE_ERROR_BUFFER_TOO_SMALL), "ERROR_BUFFER_TOO_SMALL");
  EXPECT_STREQ(filigree_status_name(12345), "UNKNOWN_STATUS");
  // The gRPC codes keep their numbers.
  EXPECT_EQ(FILIGREE_PERMISSION_DENIED, 7);
  EXPECT_EQ(FILIGREE_UNAVAILABLE, 14);
  EXPECT_EQ(FILIGREE_UNAUTHENTICATED, 16);
}

TEST(CApiErrors, NullAndBadHandles) {
  size_t n = 0;
  float buffer[3];
  uint64_t version = 0;
  int updated = 0;
  EXPECT_EQ(filigree_client_set_decode_threads(nullptr, 1), FILIGREE_ERROR_INVALID_HANDLE);
  EXPECT_NE(last_error().find("filigree_client_set_decode_threads"), std::string::npos) << last_error();
  EXPECT_EQ(filigree_session_vertex_count(nullptr, &n), FILIGREE_ERROR_INVALID_HANDLE);
  EXPECT_FALSE(last_error().empty());
  EXPECT_EQ(filigree_driver_poll(nullptr, buffer, 3, &version, nullptr, &updated), FILIGREE_ERROR_INVALID_HANDLE);
  EXPECT_EQ(filigree_driver_send_positions(nullptr, 1, buffer, 3), FILIGREE_ERROR_INVALID_HANDLE);
  EXPECT_EQ(filigree_watcher_poll(nullptr, buffer, 3, nullptr, nullptr, nullptr), FILIGREE_ERROR_INVALID_HANDLE);
  EXPECT_EQ(filigree_watcher_wait(nullptr, 0), FILIGREE_ERROR_INVALID_HANDLE);
  EXPECT_EQ(filigree_join(nullptr, "s", "t", nullptr), FILIGREE_ERROR_INVALID_HANDLE);
  EXPECT_EQ(filigree_driver_close(nullptr), FILIGREE_ERROR_INVALID_HANDLE);
  // The message functions never return NULL.
  EXPECT_GT(std::strlen(filigree_client_last_error(nullptr)), 0u);
  EXPECT_GT(std::strlen(filigree_driver_last_error(nullptr)), 0u);
  // free(NULL) is a no-op, as in C.
  EXPECT_EQ(filigree_client_free(nullptr), FILIGREE_OK);
  EXPECT_EQ(filigree_session_free(nullptr), FILIGREE_OK);
  EXPECT_EQ(filigree_driver_free(nullptr), FILIGREE_OK);
  EXPECT_EQ(filigree_watcher_free(nullptr), FILIGREE_OK);

  // A handle of another kind (an IntPtr mix-up), and a freed one.
  filigree_client* client = nullptr;
  ASSERT_EQ(filigree_connect("127.0.0.1:1", nullptr, &client), FILIGREE_OK) << last_error();
  ASSERT_NE(client, nullptr);
  EXPECT_EQ(filigree_session_vertex_count(reinterpret_cast<filigree_session*>(client), &n),
            FILIGREE_ERROR_INVALID_HANDLE);
  EXPECT_EQ(filigree_driver_free(reinterpret_cast<filigree_driver*>(client)), FILIGREE_ERROR_INVALID_HANDLE);
  EXPECT_EQ(filigree_client_set_decode_threads(client, 2), FILIGREE_OK);
  EXPECT_EQ(filigree_client_free(client), FILIGREE_OK);
  EXPECT_EQ(filigree_client_free(client), FILIGREE_ERROR_INVALID_HANDLE);  // double free, caught
  EXPECT_FALSE(last_error().empty());
}

TEST(CApiErrors, NullArgumentsOfConnect) {
  filigree_client* client = reinterpret_cast<filigree_client*>(0x1);
  EXPECT_EQ(filigree_connect("127.0.0.1:1", nullptr, nullptr), FILIGREE_ERROR_NULL_ARGUMENT);
  EXPECT_NE(last_error().find("out"), std::string::npos) << last_error();
  EXPECT_EQ(filigree_connect(nullptr, nullptr, &client), FILIGREE_ERROR_NULL_ARGUMENT);
  EXPECT_EQ(client, nullptr);  // cleared on failure
  EXPECT_EQ(filigree_connect("", nullptr, &client), FILIGREE_INVALID_ARGUMENT);
  filigree_connect_options tls{};
  tls.pem_cert_chain = "-----BEGIN CERTIFICATE-----";  // a chain without its key
  EXPECT_EQ(filigree_connect("127.0.0.1:1", &tls, &client), FILIGREE_INVALID_ARGUMENT);
  EXPECT_NE(last_error().find("pem_private_key"), std::string::npos) << last_error();
}

TEST(CApiErrors, TheThreadsMessageIsPerThread) {
  EXPECT_EQ(filigree_driver_close(nullptr), FILIGREE_ERROR_INVALID_HANDLE);
  std::string other = "unset";
  std::thread([&] { other = last_error(); }).join();
  EXPECT_EQ(other, "");
  EXPECT_NE(last_error().find("filigree_driver_close"), std::string::npos);
}

TEST(CApiErrors, AServerThatIsDownIsUnavailable) {
  filigree_client* client = nullptr;
  ASSERT_EQ(filigree_connect("127.0.0.1:1", nullptr, &client), FILIGREE_OK);
  filigree_session* session = reinterpret_cast<filigree_session*>(0x1);
  EXPECT_EQ(filigree_join(client, "abc", "token", &session), FILIGREE_UNAVAILABLE);
  EXPECT_EQ(session, nullptr);
  EXPECT_NE(std::string(filigree_client_last_error(client)).find("UNAVAILABLE"), std::string::npos);
  EXPECT_EQ(filigree_client_free(client), FILIGREE_OK);
}

// ---------------------------------------------------------------- against a server

class CApiServer : public ::testing::Test {
 protected:
  void SetUp() override {
    data_dir_ = std::filesystem::path(::testing::TempDir()) /
                ("filigree_c_api_" + std::to_string(::getpid()) + "_" +
                 ::testing::UnitTest::GetInstance()->current_test_info()->name());
    std::filesystem::remove_all(data_dir_);
    server_ = std::make_unique<filigree::test::ServerProcess>(
        FILIGREE_SERVER_BINARY, std::vector<std::string>{"--data-dir", data_dir_.string()});
    ASSERT_EQ(filigree_connect(server_->address().c_str(), nullptr, &client_), FILIGREE_OK) << last_error();
  }
  void TearDown() override {
    filigree_session_free(session_);
    filigree_client_free(client_);
    server_.reset();
    std::filesystem::remove_all(data_dir_);
  }

  // Uploads bunny_small (150 base vertices, as the e2e tests do) into session_.
  void upload() {
    const std::string bytes = filigree::test::file_bytes(filigree::test::shipped_path("bunny_small.obj"));
    filigree_session_options options{};
    options.base_vertices = 150;
    ASSERT_EQ(filigree_create_session(client_, bytes.data(), bytes.size(), "obj", &options, "test_c_api", &session_),
              FILIGREE_OK)
        << last_error();
    ASSERT_EQ(filigree_session_vertex_count(session_, &n_), FILIGREE_OK);
    ASSERT_EQ(filigree_session_base_vertex_count(session_, &m_), FILIGREE_OK);
    rest_.resize(3 * n_);
    base_.resize(3 * m_);
    ASSERT_EQ(filigree_session_rest_positions(session_, rest_.data(), rest_.size(), nullptr), FILIGREE_OK);
    ASSERT_EQ(filigree_session_base_positions(session_, base_.data(), base_.size(), nullptr), FILIGREE_OK);
    session_id_ = string_of(filigree_session_id);
    editor_token_ = string_of(filigree_session_editor_token);
    float lo[3] = {1e30f, 1e30f, 1e30f}, hi[3] = {-1e30f, -1e30f, -1e30f};
    for (std::size_t i = 0; i < rest_.size(); ++i)
      lo[i % 3] = std::min(lo[i % 3], rest_[i]), hi[i % 3] = std::max(hi[i % 3], rest_[i]);
    diagonal_ = std::sqrt(double(hi[0] - lo[0]) * (hi[0] - lo[0]) + double(hi[1] - lo[1]) * (hi[1] - lo[1]) +
                          double(hi[2] - lo[2]) * (hi[2] - lo[2]));
  }

  // A session string through the size query and the copy.
  std::string string_of(int (*get)(const filigree_session*, char*, size_t, size_t*)) {
    return string_from(get, static_cast<const filigree_session*>(session_));
  }

  // Waits for and polls `driver`'s frames until one answers `pose_id`, into `positions`.
  static filigree_frame_info poll_until(filigree_driver* driver, uint64_t pose_id, std::vector<float>& positions) {
    const auto deadline = Clock::now() + std::chrono::seconds(30);
    uint64_t version = 0, got = 0;
    int updated = 0;
    while (Clock::now() < deadline) {
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now());
      int rc = filigree_driver_wait_frame(driver, std::max<int64_t>(left.count(), 0));
      if (rc == FILIGREE_DEADLINE_EXCEEDED) break;
      EXPECT_EQ(rc, FILIGREE_OK) << filigree_driver_last_error(driver);
      if (rc != FILIGREE_OK) break;
      rc = filigree_driver_poll(driver, positions.data(), positions.size(), &version, &got, &updated);
      EXPECT_EQ(rc, FILIGREE_OK) << filigree_driver_last_error(driver);
      EXPECT_EQ(updated, 1) << "wait_frame said a frame was waiting";
      if (rc != FILIGREE_OK) break;
      if (got >= pose_id) {
        filigree_frame_info info{};
        EXPECT_EQ(filigree_driver_frame_info(driver, &info), FILIGREE_OK);
        EXPECT_EQ(info.version, version);
        EXPECT_EQ(info.pose_id, got);
        return info;
      }
    }
    ADD_FAILURE() << "no frame for pose " << pose_id;
    return {};
  }

  // A string of any handle (a session's id, a driver's changes, …), through
  // the size query and the copy.
  template <class H>
  static std::string string_from(int (*get)(const H*, char*, size_t, size_t*), const H* handle) {
    size_t required = 0;
    EXPECT_EQ(get(handle, nullptr, 0, &required), FILIGREE_ERROR_BUFFER_TOO_SMALL);
    std::string s(required, '\0');
    EXPECT_EQ(get(handle, s.data(), s.size(), nullptr), FILIGREE_OK);
    s.resize(required - 1);
    return s;
  }

  // The session's current frame as the C++ client decodes it (`filigree
  // watch`, another process): a new watcher first gets the current frame's
  // keyframe when that frame is not one itself, so it waits for 1 or 2.
  std::vector<float> reference_frame(bool current_is_keyframe, uint64_t expected_version) {
    const std::filesystem::path out = data_dir_ / "reference.ply";
    std::filesystem::remove(out);
    ::setenv("FILIGREE_TOKEN", editor_token_.c_str(), 1);  // the child's environment, never its command line
    const std::string command = std::string("timeout 60 '") + FILIGREE_CLI_BINARY + "' watch --server " +
                                server_->address() + " --session " + session_id_ +
                                " --frames " + (current_is_keyframe ? "1" : "2") + " -o '" + out.string() + "' 2>&1";
    FILE* pipe = ::popen(command.c_str(), "r");
    if (!pipe) return {};
    std::string output;
    char line[512];
    while (std::fgets(line, sizeof line, pipe)) output += line;
    EXPECT_EQ(::pclose(pipe), 0) << output;
    ::unsetenv("FILIGREE_TOKEN");
    // Its last frame must be the one the driver polled.
    const std::size_t at = output.rfind("version ");
    EXPECT_NE(at, std::string::npos) << output;
    if (at != std::string::npos) {
      EXPECT_EQ(std::stoull(output.substr(at + 8)), expected_version) << output;
    }
    return read_ply_positions(out);
  }

  // The vertices of the binary PLY `filigree watch` writes (x y z doubles,
  // little-endian, from the decoded floats: exact), in the session's order.
  static std::vector<float> read_ply_positions(const std::filesystem::path& path) {
    const std::string bytes = filigree::test::file_bytes(path.string());
    const std::size_t header_end = bytes.find("end_header\n");
    const std::size_t count_at = bytes.find("element vertex ");
    EXPECT_NE(header_end, std::string::npos);
    EXPECT_NE(bytes.find("format binary_little_endian"), std::string::npos);
    EXPECT_NE(bytes.find("property double x\nproperty double y\nproperty double z\n"), std::string::npos);
    if (header_end == std::string::npos || count_at == std::string::npos) return {};
    const std::size_t count = std::stoull(bytes.substr(count_at + 15));
    const char* data = bytes.data() + header_end + 11;
    if (bytes.size() < header_end + 11 + 24 * count) return {};
    std::vector<float> positions(3 * count);
    for (std::size_t i = 0; i < 3 * count; ++i) {
      double x;
      std::memcpy(&x, data + 8 * i, 8);
      positions[i] = static_cast<float>(x);
    }
    return positions;
  }

  // The largest coordinate difference.
  static double max_difference(const std::vector<float>& a, const std::vector<float>& b) {
    EXPECT_EQ(a.size(), b.size());
    double worst = 0.0;
    for (std::size_t i = 0; i < std::min(a.size(), b.size()); ++i) worst = std::max(worst, double(std::fabs(a[i] - b[i])));
    return worst;
  }

  // A pose: the base mesh's far half along its longest axis bent by up to `degrees`.
  std::vector<float> bend(double degrees) const {
    float lo[3] = {1e30f, 1e30f, 1e30f}, hi[3] = {-1e30f, -1e30f, -1e30f};
    for (std::size_t i = 0; i < base_.size(); ++i)
      lo[i % 3] = std::min(lo[i % 3], base_[i]), hi[i % 3] = std::max(hi[i % 3], base_[i]);
    int a = 0;
    for (int c = 1; c < 3; ++c)
      if (hi[c] - lo[c] > hi[a] - lo[a]) a = c;
    const int b = (a + 1) % 3;
    const double mid = 0.5 * (lo[a] + hi[a]), half = 0.5 * (hi[a] - lo[a]), center_b = 0.5 * (lo[b] + hi[b]);
    std::vector<float> out = base_;
    for (std::size_t v = 0; v < m_; ++v) {
      const double u = base_[3 * v + a] - mid;
      if (u <= 0.0) continue;
      const double angle = degrees * std::numbers::pi / 180.0 * (u / half), db = base_[3 * v + b] - center_b;
      out[3 * v + a] = float(mid + u * std::cos(angle) - db * std::sin(angle));
      out[3 * v + b] = float(center_b + u * std::sin(angle) + db * std::cos(angle));
    }
    return out;
  }

  std::filesystem::path data_dir_;
  std::unique_ptr<filigree::test::ServerProcess> server_;
  filigree_client* client_ = nullptr;
  filigree_session* session_ = nullptr;
  size_t n_ = 0, m_ = 0;
  std::vector<float> rest_, base_;
  std::string session_id_, editor_token_;
  double diagonal_ = 0.0;
};

// Skeletal poses and clips through the C API, on a skinned GLB made here
// (the shipped bunny with the automatic chain rig).
TEST_F(CApiServer, JointPosesAndClipsOfASkinnedUpload) {
  const filigree::TriMesh bunny = filigree::repair_mesh(filigree::test::shipped_mesh("bunny_small.obj"), {}, nullptr);
  const filigree::Rig rig = filigree::auto_rig(bunny, {.joints = 4});
  const std::filesystem::path glb = data_dir_ / "rigged.glb";
  std::filesystem::create_directories(data_dir_);
  filigree::write_glb_rigged(bunny, rig, glb);
  const std::string bytes = filigree::test::file_bytes(glb.string());
  ASSERT_EQ(filigree_create_session(client_, bytes.data(), bytes.size(), "glb", nullptr, "test_c_api", &session_), FILIGREE_OK)
      << last_error();
  size_t joints = 0, clips = 0, n = 0;
  ASSERT_EQ(filigree_session_joint_count(session_, &joints), FILIGREE_OK);
  ASSERT_EQ(filigree_session_clip_count(session_, &clips), FILIGREE_OK);
  ASSERT_EQ(filigree_session_vertex_count(session_, &n), FILIGREE_OK);
  EXPECT_EQ(joints, 4u);
  EXPECT_EQ(clips, 2u);
  std::vector<float> rest(3 * n), positions(3 * n);
  ASSERT_EQ(filigree_session_rest_positions(session_, rest.data(), rest.size(), nullptr), FILIGREE_OK);

  filigree_driver* driver = nullptr;
  ASSERT_EQ(filigree_driver_open(session_, nullptr, "c-skeleton", &driver), FILIGREE_OK) << last_error();
  // Every joint at rest (NULL joints: all, in order) gives the rest mesh.
  std::vector<float> values;
  for (const filigree::Joint& j : rig.joints)
    for (const double c : {j.rest.translation.x(), j.rest.translation.y(), j.rest.translation.z(), 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0})
      values.push_back(static_cast<float>(c));
  ASSERT_EQ(filigree_driver_send_joints(driver, 1, FILIGREE_JOINTS_LOCAL_TRS, nullptr, 0, values.data(), values.size()),
            FILIGREE_OK) << filigree_driver_last_error(driver);
  const filigree_frame_info at_rest = poll_until(driver, 1, positions);
  double worst = 0.0;
  for (std::size_t i = 0; i < rest.size(); ++i) worst = std::max(worst, double(std::abs(positions[i] - rest[i])));
  EXPECT_LE(worst, double(at_rest.max_error) + 1e-6);
  // One joint bent (a partial skeletal pose): the mesh moves.
  const uint32_t one[] = {2};
  const float bend[] = {values[20], values[21], values[22], 0.0f, 0.0f, 0.5f, 0.8660254f, 1.0f, 1.0f, 1.0f};
  EXPECT_EQ(filigree_driver_send_joints(driver, 2, FILIGREE_JOINTS_LOCAL_TRS, one, 1, bend, 9),
            FILIGREE_INVALID_ARGUMENT);  // 9 values for one joint: refused here, the stream goes on
  // A zero rotation quaternion: refused here, naming the joint (2), not its
  // place in the message (0).
  const float zero_rotation[] = {values[20], values[21], values[22], 0.0f, 0.0f, 0.0f, 0.0f, 1.0f, 1.0f, 1.0f};
  EXPECT_EQ(filigree_driver_send_joints(driver, 2, FILIGREE_JOINTS_LOCAL_TRS, one, 1, zero_rotation, 10),
            FILIGREE_INVALID_ARGUMENT);
  EXPECT_NE(std::string(filigree_driver_last_error(driver)).find("joint 2 has a zero rotation quaternion"), std::string::npos)
      << filigree_driver_last_error(driver);
  ASSERT_EQ(filigree_driver_send_joints(driver, 2, FILIGREE_JOINTS_LOCAL_TRS, one, 1, bend, 10), FILIGREE_OK)
      << filigree_driver_last_error(driver);
  poll_until(driver, 2, positions);
  worst = 0.0;
  for (std::size_t i = 0; i < rest.size(); ++i) worst = std::max(worst, double(std::abs(positions[i] - rest[i])));
  EXPECT_GT(worst, 0.01 * filigree::bounding_box_diagonal(bunny.positions));
  EXPECT_EQ(filigree_driver_close(driver), FILIGREE_OK) << filigree_driver_last_error(driver);
  EXPECT_EQ(filigree_driver_free(driver), FILIGREE_OK);

  // The server plays a clip; the watcher ends normally after its last sample.
  filigree_watcher* clip = nullptr;
  ASSERT_EQ(filigree_play_clip(session_, nullptr, "bend", 8.0, 0, nullptr, nullptr, &clip), FILIGREE_OK) << last_error();
  EXPECT_EQ(filigree_watcher_wait(clip, 30000), FILIGREE_OK) << filigree_watcher_last_error(clip);
  filigree_frame_info info{};
  EXPECT_EQ(filigree_watcher_frame_info(clip, &info), FILIGREE_OK);
  EXPECT_GE(info.frames_received, 2u);
  EXPECT_EQ(filigree_watcher_free(clip), FILIGREE_OK);
  filigree_watcher* missing = nullptr;
  ASSERT_EQ(filigree_play_clip(session_, nullptr, "nope", 1.0, 0, nullptr, nullptr, &missing), FILIGREE_OK);
  EXPECT_EQ(filigree_watcher_wait(missing, 30000), FILIGREE_NOT_FOUND);
  EXPECT_NE(std::string(filigree_watcher_last_error(missing)).find("no clip 'nope'"), std::string::npos)
      << filigree_watcher_last_error(missing);
  EXPECT_EQ(filigree_watcher_free(missing), FILIGREE_OK);

  // From a start time, at most max_rate samples per second: every frame says
  // which clip time it shows. The server takes sample k (pose_id) no sooner
  // than 1/max_rate s of clip time after sample k − 1, so its clip time is at
  // least start_seconds + (k − 1)/max_rate; the last is at the duration.
  double duration = -1.0;
  for (size_t c = 0; c < clips; ++c) {
    char name[64];
    ASSERT_EQ(filigree_session_clip_name(session_, c, name, sizeof name, nullptr), FILIGREE_OK);
    if (std::string(name) == "bend") {
      ASSERT_EQ(filigree_session_clip_duration(session_, c, &duration), FILIGREE_OK);
    }
  }
  ASSERT_GT(duration, 1.0);
  const filigree_clip_playback ranged{.speed = 1.0, .loop = 0, .start_seconds = duration - 1.0, .max_rate = 5.0};
  const double spacing = 1.0 / ranged.max_rate;  // clip seconds from one sample to the next, at least
  filigree_watcher* from = nullptr;
  ASSERT_EQ(filigree_play_clip_with(session_, nullptr, "bend", &ranged, nullptr, nullptr, &from), FILIGREE_OK)
      << last_error();
  uint64_t last_version = 0, samples = 0;
  size_t polled = 0;
  double shown = 0.0;
  for (;;) {
    const int waited = filigree_watcher_wait_frame(from, 30000);
    if (waited == FILIGREE_ERROR_STREAM_ENDED) break;  // ended normally, its last frame polled
    ASSERT_EQ(waited, FILIGREE_OK) << filigree_watcher_last_error(from);
    uint64_t version = 0, pose_id = 0;
    int updated = 0;
    ASSERT_EQ(filigree_watcher_poll(from, positions.data(), positions.size(), &version, &pose_id, &updated), FILIGREE_OK)
        << filigree_watcher_last_error(from);
    ASSERT_EQ(updated, 1) << "wait_frame said a frame was waiting";
    filigree_frame_info polled_info{};
    double seconds = -1.0;
    ASSERT_EQ(filigree_watcher_frame_info(from, &polled_info), FILIGREE_OK);
    ASSERT_EQ(filigree_watcher_clip_seconds(from, &seconds), FILIGREE_OK) << filigree_watcher_last_error(from);
    // (A keyframe the stream had not sent may come before a frame with an older version.)
    if (polled > 0 && polled_info.keyframe && version < last_version) continue;
    last_version = version;
    ++polled;
    if (pose_id == 0) {  // the session's frame from before the first sample
      EXPECT_EQ(seconds, 0.0) << "version " << version;
      continue;
    }
    EXPECT_GE(pose_id, samples);
    EXPECT_GE(seconds, shown) << "sample " << pose_id;  // never back in a clip that does not loop
    EXPECT_GE(seconds, ranged.start_seconds + double(pose_id - 1) * spacing - 1e-9) << "sample " << pose_id;
    EXPECT_LE(seconds, duration) << "sample " << pose_id;
    samples = pose_id;
    shown = seconds;
  }
  EXPECT_EQ(filigree_watcher_wait(from, 30000), FILIGREE_OK) << filigree_watcher_last_error(from);
  EXPECT_DOUBLE_EQ(shown, duration);  // the last frame shows the clip's end
  // Samples 1…K−1 lie before the duration (the first at or past it is the
  // last, K), each at least `spacing` after the one before:
  // (K − 2)·spacing < duration − start_seconds.
  EXPECT_GE(samples, 2u);
  EXPECT_LE(samples, static_cast<uint64_t>(std::floor((duration - ranged.start_seconds) / spacing)) + 2);
  EXPECT_EQ(filigree_watcher_free(from), FILIGREE_OK);

  // NULL options are the defaults (the whole clip, once); a callback's
  // watcher tells the clip time of the frame it handed over last.
  std::atomic<size_t> handed{0};
  const filigree_frame_callback count = [](const float*, size_t, uint64_t, void* user) {
    ++*static_cast<std::atomic<size_t>*>(user);
  };
  filigree_watcher* whole = nullptr;
  ASSERT_EQ(filigree_play_clip_with(session_, nullptr, "bend", nullptr, count, &handed, &whole), FILIGREE_OK)
      << last_error();
  EXPECT_EQ(filigree_watcher_wait(whole, 30000), FILIGREE_OK) << filigree_watcher_last_error(whole);
  double end_seconds = -1.0;
  ASSERT_EQ(filigree_watcher_clip_seconds(whole, &end_seconds), FILIGREE_OK);
  EXPECT_DOUBLE_EQ(end_seconds, duration);
  EXPECT_GE(handed.load(), 2u);
  EXPECT_EQ(filigree_watcher_clip_seconds(whole, nullptr), FILIGREE_ERROR_NULL_ARGUMENT);
  EXPECT_EQ(filigree_watcher_free(whole), FILIGREE_OK);

  // The CLI's `play` passes --start and prints each frame's clip time.
  const double start = duration - 0.5;
  ::setenv("FILIGREE_TOKEN", string_of(filigree_session_editor_token).c_str(), 1);  // never on a command line
  const std::string command = std::string("timeout 60 '") + FILIGREE_CLI_BINARY + "' play --server " +
                              server_->address() + " --session " + string_of(filigree_session_id) +
                              " --clip bend --fps 10 --start " + std::to_string(start) + " 2>&1";
  FILE* pipe = ::popen(command.c_str(), "r");
  ASSERT_NE(pipe, nullptr);
  std::vector<double> times;
  std::string output;
  char line[512];
  while (std::fgets(line, sizeof line, pipe)) {
    output += line;
    // "version V  sample S  clip_time T s …"; sample 0: the frame from before the first sample.
    if (const char* at = std::strstr(line, "clip_time "); at && !std::strstr(line, "sample 0 ")) times.push_back(std::atof(at + 10));
  }
  EXPECT_EQ(::pclose(pipe), 0) << output;
  ::unsetenv("FILIGREE_TOKEN");
  ASSERT_FALSE(times.empty()) << output;
  for (const double t : times) EXPECT_GE(t, start - 1e-3) << output;
  EXPECT_NEAR(times.back(), duration, 1e-3) << output;
}

// filigree_play_clip_with checks its numbers before anything is sent: a bad
// one is FILIGREE_INVALID_ARGUMENT naming it, and no watcher. (The session
// has no skeleton: a check left to the server would answer OK here, and the
// stream would end with FAILED_PRECONDITION later.)
TEST_F(CApiServer, PlayClipWithRefusesBadNumbersAtTheCall) {
  upload();
  const double nan = std::numeric_limits<double>::quiet_NaN(), inf = std::numeric_limits<double>::infinity();
  const auto playback = [](double speed, double start_seconds, double max_rate) {
    return filigree_clip_playback{.speed = speed, .loop = 0, .start_seconds = start_seconds, .max_rate = max_rate};
  };
  struct Case {
    filigree_clip_playback options;
    const char* names;  // what the message must name
  };
  const Case cases[] = {
      {playback(-1.0, 0.0, 0.0), "speed must be finite and >= 0"},
      {playback(nan, 0.0, 0.0), "speed must be finite and >= 0"},
      {playback(inf, 0.0, 0.0), "speed must be finite and >= 0"},
      {playback(1.0, 0.0, -5.0), "max_rate must be finite and >= 0"},
      {playback(1.0, 0.0, nan), "max_rate must be finite and >= 0"},
      {playback(1.0, 0.0, inf), "max_rate must be finite and >= 0"},
      {playback(1.0, nan, 0.0), "start_seconds must be finite"},
      {playback(1.0, -inf, 0.0), "start_seconds must be finite"},
  };
  for (const Case& c : cases) {
    filigree_watcher* watcher = reinterpret_cast<filigree_watcher*>(&n_);  // not NULL: the call must clear it
    EXPECT_EQ(filigree_play_clip_with(session_, nullptr, "bend", &c.options, nullptr, nullptr, &watcher),
              FILIGREE_INVALID_ARGUMENT) << c.names;
    EXPECT_EQ(watcher, nullptr) << c.names;
    EXPECT_NE(last_error().find(std::string("filigree_play_clip_with: ") + c.names), std::string::npos) << last_error();
    EXPECT_NE(std::string(filigree_session_last_error(session_)).find(c.names), std::string::npos)
        << filigree_session_last_error(session_);
  }
  // filigree_play_clip keeps its signature and checks its speed the same way.
  filigree_watcher* watcher = nullptr;
  EXPECT_EQ(filigree_play_clip(session_, nullptr, "bend", nan, 0, nullptr, nullptr, &watcher), FILIGREE_INVALID_ARGUMENT);
  EXPECT_EQ(watcher, nullptr);
  EXPECT_NE(last_error().find("filigree_play_clip: speed must be finite and >= 0"), std::string::npos) << last_error();
  // NULL clip and out, and NULL session, as every call.
  const filigree_clip_playback defaults{};
  EXPECT_EQ(filigree_play_clip_with(session_, nullptr, nullptr, &defaults, nullptr, nullptr, &watcher),
            FILIGREE_ERROR_NULL_ARGUMENT);
  EXPECT_EQ(filigree_play_clip_with(session_, nullptr, "bend", &defaults, nullptr, nullptr, nullptr),
            FILIGREE_ERROR_NULL_ARGUMENT);
  EXPECT_EQ(filigree_play_clip_with(nullptr, nullptr, "bend", &defaults, nullptr, nullptr, &watcher),
            FILIGREE_ERROR_INVALID_HANDLE);
  // -0 and zeros are valid ({0}: the defaults); the stream then ends because
  // this session has no skeleton, as the server says.
  const filigree_clip_playback zeros{.speed = -0.0, .loop = 0, .start_seconds = -0.0, .max_rate = -0.0};
  ASSERT_EQ(filigree_play_clip_with(session_, nullptr, "bend", &zeros, nullptr, nullptr, &watcher), FILIGREE_OK)
      << last_error();
  EXPECT_EQ(filigree_watcher_wait(watcher, 30000), FILIGREE_FAILED_PRECONDITION) << filigree_watcher_last_error(watcher);
  double seconds = -1.0;
  EXPECT_EQ(filigree_watcher_clip_seconds(watcher, &seconds), FILIGREE_OK);
  EXPECT_EQ(seconds, 0.0);  // no frame
  EXPECT_EQ(filigree_watcher_free(watcher), FILIGREE_OK);
}

TEST_F(CApiServer, UnknownSessionAndBadTokenGiveTheGrpcCodes) {
  filigree_session* joined = nullptr;
  EXPECT_EQ(filigree_join(client_, "no-such-session", "token", &joined), FILIGREE_NOT_FOUND);
  EXPECT_EQ(joined, nullptr);
  EXPECT_NE(std::string(filigree_client_last_error(client_)).find("NOT_FOUND"), std::string::npos)
      << filigree_client_last_error(client_);
  EXPECT_NE(last_error().find("NOT_FOUND"), std::string::npos);

  upload();
  EXPECT_EQ(filigree_join(client_, session_id_.c_str(), "not-a-token", &joined), FILIGREE_NOT_FOUND);
  EXPECT_FALSE(std::string(filigree_client_last_error(client_)).empty());

  // A joined session: the viewer token joins, but may not drive.
  const std::string viewer = string_of(filigree_session_viewer_token);
  ASSERT_EQ(filigree_join(client_, session_id_.c_str(), viewer.c_str(), &joined), FILIGREE_OK) << last_error();
  size_t n = 0, required = 7;
  EXPECT_EQ(filigree_session_vertex_count(joined, &n), FILIGREE_OK);
  EXPECT_EQ(n, n_);
  EXPECT_EQ(filigree_session_editor_token(joined, nullptr, 0, &required), FILIGREE_ERROR_BUFFER_TOO_SMALL);
  EXPECT_EQ(required, 1u);  // empty for a joined session: just the NUL
  filigree_driver* driver = nullptr;
  ASSERT_EQ(filigree_driver_open(joined, nullptr, "viewer", &driver), FILIGREE_OK);
  // The session knows its token is a viewer's (JoinSession says so): every
  // send is refused at once, and nothing reaches the server.
  std::vector<float> frame(3 * n_);
  EXPECT_EQ(filigree_driver_send_positions(driver, 1, base_.data(), base_.size()), FILIGREE_PERMISSION_DENIED);
  EXPECT_NE(std::string(filigree_driver_last_error(driver)).find("viewer token, which cannot drive"), std::string::npos)
      << filigree_driver_last_error(driver);
  EXPECT_EQ(filigree_driver_send_positions(driver, 2, base_.data(), base_.size()), FILIGREE_PERMISSION_DENIED);
  EXPECT_EQ(filigree_driver_free(driver), FILIGREE_OK);
  // Given the viewer token explicitly, the server refuses it: in a send or a
  // poll, then in close.
  ASSERT_EQ(filigree_driver_open(joined, viewer.c_str(), "viewer", &driver), FILIGREE_OK);
  int rc = filigree_driver_send_positions(driver, 1, base_.data(), base_.size());
  if (rc == FILIGREE_OK) rc = filigree_driver_wait_frame(driver, 30000);  // the stream ends without a frame
  EXPECT_EQ(rc, FILIGREE_PERMISSION_DENIED) << filigree_driver_last_error(driver);
  EXPECT_EQ(filigree_driver_poll(driver, frame.data(), frame.size(), nullptr, nullptr, nullptr),
            FILIGREE_PERMISSION_DENIED);
  EXPECT_NE(std::string(filigree_driver_last_error(driver)).find("PERMISSION_DENIED"), std::string::npos);
  EXPECT_EQ(filigree_driver_close(driver), FILIGREE_PERMISSION_DENIED);
  EXPECT_EQ(filigree_driver_free(driver), FILIGREE_OK);
  // Closing needs the editor token.
  EXPECT_EQ(filigree_close_session(joined, nullptr), FILIGREE_PERMISSION_DENIED);
  EXPECT_EQ(filigree_session_free(joined), FILIGREE_OK);
}

TEST_F(CApiServer, BuffersAndIndicesAreChecked) {
  upload();
  ASSERT_EQ(n_, 1839u);
  ASSERT_EQ(m_, 150u);
  size_t required = 0;
  std::vector<float> small(10);
  // Size query, too small (nothing written), NULL with a capacity, exact.
  EXPECT_EQ(filigree_session_rest_positions(session_, nullptr, 0, &required), FILIGREE_ERROR_BUFFER_TOO_SMALL);
  EXPECT_EQ(required, 3 * n_);
  required = 0;
  EXPECT_EQ(filigree_session_rest_positions(session_, small.data(), small.size(), &required),
            FILIGREE_ERROR_BUFFER_TOO_SMALL);
  EXPECT_EQ(required, 3 * n_);
  EXPECT_EQ(small, std::vector<float>(10));
  EXPECT_NE(std::string(filigree_session_last_error(session_)).find("5517"), std::string::npos)
      << filigree_session_last_error(session_);
  EXPECT_EQ(filigree_session_rest_positions(session_, small.data(), small.size(), nullptr),
            FILIGREE_ERROR_BUFFER_TOO_SMALL);
  EXPECT_EQ(filigree_session_rest_positions(session_, nullptr, 100, &required), FILIGREE_ERROR_NULL_ARGUMENT);
  EXPECT_FALSE(std::string(filigree_session_last_error(session_)).empty());
  EXPECT_EQ(filigree_session_vertex_count(session_, nullptr), FILIGREE_ERROR_NULL_ARGUMENT);

  std::vector<uint32_t> faces, ids(m_);
  EXPECT_EQ(filigree_session_rest_faces(session_, nullptr, 0, &required), FILIGREE_ERROR_BUFFER_TOO_SMALL);
  faces.resize(required);
  EXPECT_EQ(filigree_session_rest_faces(session_, faces.data(), faces.size(), nullptr), FILIGREE_OK);
  EXPECT_EQ(faces.size() % 3, 0u);
  EXPECT_LT(*std::max_element(faces.begin(), faces.end()), n_);
  EXPECT_EQ(filigree_session_base_original_ids(session_, ids.data(), ids.size(), &required), FILIGREE_OK);
  EXPECT_EQ(required, m_);
  // Base vertex j is session vertex ids[j]: same rest position.
  for (std::size_t j = 0; j < m_; ++j)
    for (int c = 0; c < 3; ++c) EXPECT_EQ(base_[3 * j + c], rest_[3 * ids[j] + c]);
  std::vector<uint32_t> uploaded(n_);
  EXPECT_EQ(filigree_session_uploaded_ids(session_, uploaded.data(), uploaded.size(), &required), FILIGREE_OK);
  EXPECT_EQ(required, n_);

  // The session id string: capacity counts the NUL.
  std::string id(session_id_.size(), '\0');
  EXPECT_EQ(filigree_session_id(session_, id.data(), id.size(), &required), FILIGREE_ERROR_BUFFER_TOO_SMALL);
  EXPECT_EQ(required, session_id_.size() + 1);

  // No skeleton: indices out of range, joints refused before the wire.
  size_t joints = 9, clips = 9;
  int32_t parent = 0;
  double seconds = 0;
  EXPECT_EQ(filigree_session_joint_count(session_, &joints), FILIGREE_OK);
  EXPECT_EQ(joints, 0u);
  EXPECT_EQ(filigree_session_clip_count(session_, &clips), FILIGREE_OK);
  EXPECT_EQ(clips, 0u);
  EXPECT_EQ(filigree_session_joint_parent(session_, 0, &parent), FILIGREE_OUT_OF_RANGE);
  EXPECT_EQ(filigree_session_joint_name(session_, 0, nullptr, 0, nullptr), FILIGREE_OUT_OF_RANGE);
  EXPECT_EQ(filigree_session_clip_duration(session_, 3, &seconds), FILIGREE_OUT_OF_RANGE);

  filigree_driver* driver = nullptr;
  ASSERT_EQ(filigree_driver_open(session_, nullptr, "checks", &driver), FILIGREE_OK) << last_error();
  std::vector<float> frame(3 * n_);
  float trs[10] = {0, 0, 0, 0, 0, 0, 1, 1, 1, 1};
  EXPECT_EQ(filigree_driver_send_joints(driver, 1, FILIGREE_JOINTS_LOCAL_TRS, nullptr, 0, trs, 10),
            FILIGREE_FAILED_PRECONDITION);
  EXPECT_EQ(filigree_driver_send_joints(driver, 1, 7, nullptr, 0, trs, 10), FILIGREE_INVALID_ARGUMENT);
  // Polls: NULL and short buffers, whether or not a frame waits.
  EXPECT_EQ(filigree_driver_poll(driver, nullptr, frame.size(), nullptr, nullptr, nullptr),
            FILIGREE_ERROR_NULL_ARGUMENT);
  EXPECT_EQ(filigree_driver_poll(driver, frame.data(), frame.size() - 1, nullptr, nullptr, nullptr),
            FILIGREE_ERROR_BUFFER_TOO_SMALL);
  EXPECT_NE(std::string(filigree_driver_last_error(driver)).find("5517"), std::string::npos);
  // Malformed poses are refused here, and the stream goes on.
  EXPECT_EQ(filigree_driver_send_positions(driver, 1, base_.data(), base_.size() - 1), FILIGREE_INVALID_ARGUMENT);
  EXPECT_EQ(filigree_driver_send_positions(driver, 1, nullptr, base_.size()), FILIGREE_ERROR_NULL_ARGUMENT);
  const uint32_t bad_index = static_cast<uint32_t>(m_);
  EXPECT_EQ(filigree_driver_send_partial(driver, 1, &bad_index, 1, base_.data(), 3), FILIGREE_INVALID_ARGUMENT);
  const uint32_t good_index = 0;
  EXPECT_EQ(filigree_driver_send_partial(driver, 1, &good_index, 1, base_.data(), 2), FILIGREE_INVALID_ARGUMENT);
  EXPECT_EQ(filigree_driver_send_partial(driver, 1, &good_index, 0, base_.data(), 0), FILIGREE_INVALID_ARGUMENT);
  // A NaN (as physics may give one) is an error of that send, naming the
  // base vertex; the server never sees it, so the stream goes on.
  std::vector<float> nan_pose = base_;
  nan_pose[3 * 7 + 1] = std::nanf("");
  EXPECT_EQ(filigree_driver_send_positions(driver, 1, nan_pose.data(), nan_pose.size()), FILIGREE_INVALID_ARGUMENT);
  EXPECT_NE(std::string(filigree_driver_last_error(driver)).find("base vertex 7's y is not finite"), std::string::npos)
      << filigree_driver_last_error(driver);
  const uint32_t seventh = 7;
  EXPECT_EQ(filigree_driver_send_partial(driver, 1, &seventh, 1, nan_pose.data() + 21, 3), FILIGREE_INVALID_ARGUMENT);
  EXPECT_NE(std::string(filigree_driver_last_error(driver)).find("base vertex 7's y"), std::string::npos)
      << filigree_driver_last_error(driver);
  EXPECT_EQ(filigree_driver_send_positions(driver, 1, base_.data(), base_.size()), FILIGREE_OK)
      << filigree_driver_last_error(driver);
  // Waiting for a pose: none of pose 2 can come (it was never sent), pose 1's does.
  EXPECT_EQ(filigree_driver_wait_for_pose(driver, 2, 50), FILIGREE_DEADLINE_EXCEEDED);
  EXPECT_NE(std::string(filigree_driver_last_error(driver)).find("pose 2"), std::string::npos);
  ASSERT_EQ(filigree_driver_wait_for_pose(driver, 1, 30000), FILIGREE_OK) << filigree_driver_last_error(driver);
  uint64_t answered = 0;
  int updated = 0;
  ASSERT_EQ(filigree_driver_poll(driver, frame.data(), frame.size(), nullptr, &answered, &updated), FILIGREE_OK);
  EXPECT_EQ(updated, 1);
  EXPECT_EQ(answered, 1u);
  EXPECT_EQ(filigree_driver_wait_for_pose(driver, 1, 0), FILIGREE_OK);  // polled already: at once
  EXPECT_EQ(filigree_driver_send_positions(driver, 3, base_.data(), base_.size()), FILIGREE_OK);
  poll_until(driver, 3, frame);
  EXPECT_EQ(filigree_driver_frame_info(driver, nullptr), FILIGREE_ERROR_NULL_ARGUMENT);
  EXPECT_EQ(filigree_driver_close(driver), FILIGREE_OK) << filigree_driver_last_error(driver);
  EXPECT_EQ(filigree_driver_close(driver), FILIGREE_OK);  // idempotent
  // After close: sends and polls say the stream has ended.
  EXPECT_EQ(filigree_driver_send_positions(driver, 2, base_.data(), base_.size()), FILIGREE_ERROR_STREAM_ENDED);
  EXPECT_EQ(filigree_driver_poll(driver, frame.data(), frame.size(), nullptr, nullptr, nullptr),
            FILIGREE_ERROR_STREAM_ENDED);
  EXPECT_EQ(filigree_driver_free(driver), FILIGREE_OK);
}

struct CallbackState {
  std::mutex mutex;
  std::condition_variable changed;
  std::atomic<filigree_watcher*> watcher{nullptr};
  std::atomic<int> frames{0};
  std::atomic<std::size_t> float_count{0};
  std::atomic<int> close_from_callback{-1};
};

void on_frame(const float* positions, size_t float_count, uint64_t version, void* user) {
  auto* state = static_cast<CallbackState*>(user);
  if (positions && version > 0) state->float_count = float_count;
  {
    std::lock_guard lock(state->mutex);
    ++state->frames;
  }
  state->changed.notify_all();
  // Closing its own watcher from the callback would wait for itself.
  if (filigree_watcher* w = state->watcher.load(); w && state->close_from_callback < 0)
    state->close_from_callback = filigree_watcher_close(w);
}

TEST_F(CApiServer, DrivenFramesMatchTheCppClientsDecoding) {
  upload();
  std::vector<float> frame(3 * n_);

  // Watchers from the start: one polled, one with a callback.
  filigree_watcher* polled = nullptr;
  ASSERT_EQ(filigree_watcher_open(session_, nullptr, 0, nullptr, nullptr, &polled), FILIGREE_OK) << last_error();
  CallbackState state;
  filigree_watcher* called = nullptr;
  ASSERT_EQ(filigree_watcher_open(session_, nullptr, 0, on_frame, &state, &called), FILIGREE_OK) << last_error();
  state.watcher = called;

  filigree_driver* driver = nullptr;
  ASSERT_EQ(filigree_driver_open(session_, nullptr, "test_c_api", &driver), FILIGREE_OK) << last_error();

  // 1. The rest pose: the rest mesh, within the frame's quantization error
  //    (and the solver's rounding).
  ASSERT_EQ(filigree_driver_send_positions(driver, 1, base_.data(), base_.size()), FILIGREE_OK);
  filigree_frame_info info = poll_until(driver, 1, frame);
  EXPECT_EQ(info.pose_id, 1u);
  EXPECT_LE(max_difference(frame, rest_), info.max_error + 1e-5 * diagonal_);

  // 2. A full pose: a bend. The frame moved, and it is what the C++ client
  //    decodes from the session's current frame.
  const std::vector<float> bent = bend(40.0);
  ASSERT_EQ(filigree_driver_send_positions(driver, 2, bent.data(), bent.size()), FILIGREE_OK);
  info = poll_until(driver, 2, frame);
  EXPECT_GT(max_difference(frame, rest_), 0.05 * diagonal_);
  std::vector<float> reference = reference_frame(info.keyframe != 0, info.version);
  ASSERT_EQ(reference.size(), frame.size());
  EXPECT_LE(max_difference(frame, reference), 2.0 * info.max_error + 1e-7 * diagonal_);
  std::printf("full pose: version %llu (%s), moved %.3g, vs the C++ client %.3g, max_error %.3g\n",
              static_cast<unsigned long long>(info.version), info.keyframe ? "keyframe" : "sparse",
              max_difference(frame, rest_), max_difference(frame, reference), double(info.max_error));
  std::vector<uint32_t> ids(m_);
  ASSERT_EQ(filigree_session_base_original_ids(session_, ids.data(), ids.size(), nullptr), FILIGREE_OK);

  // 3. A partial pose: five base vertices lifted by 3% of the diagonal.
  std::vector<uint32_t> moved = {0, 30, 60, 90, 120};
  std::vector<float> lifted;
  for (uint32_t j : moved)
    lifted.insert(lifted.end(), {bent[3 * j], bent[3 * j + 1] + float(0.03 * diagonal_), bent[3 * j + 2]});
  ASSERT_EQ(filigree_driver_send_partial(driver, 3, moved.data(), moved.size(), lifted.data(), lifted.size()),
            FILIGREE_OK)
      << filigree_driver_last_error(driver);
  const std::vector<float> before = frame;
  info = poll_until(driver, 3, frame);
  EXPECT_GT(max_difference(frame, before), 0.01 * diagonal_);
  reference = reference_frame(info.keyframe != 0, info.version);
  ASSERT_EQ(reference.size(), frame.size());
  EXPECT_LE(max_difference(frame, reference), 2.0 * info.max_error + 1e-7 * diagonal_);
  std::printf("partial pose: version %llu (%s), moved %.3g, vs the C++ client %.3g, max_error %.3g\n",
              static_cast<unsigned long long>(info.version), info.keyframe ? "keyframe" : "sparse",
              max_difference(frame, before), max_difference(frame, reference), double(info.max_error));
  // The lifted base vertices are where the partial pose put them.
  for (std::size_t k = 0; k < moved.size(); ++k)
    for (int c = 0; c < 3; ++c)
      EXPECT_NEAR(frame[3 * ids[moved[k]] + c], lifted[3 * k + c], info.max_error + 1e-4 * diagonal_)
          << "base vertex " << moved[k];

  // The polled watcher decodes the same frame from its own stream.
  std::vector<float> watched(3 * n_);
  uint64_t version = 0;
  int updated = 0;
  while (version < info.version) {
    ASSERT_EQ(filigree_watcher_wait_frame(polled, 30000), FILIGREE_OK) << filigree_watcher_last_error(polled);
    ASSERT_EQ(filigree_watcher_poll(polled, watched.data(), watched.size(), &version, nullptr, &updated),
              FILIGREE_OK)
        << filigree_watcher_last_error(polled);
    EXPECT_EQ(updated, 1);
  }
  ASSERT_EQ(version, info.version);
  filigree_frame_info watched_info{};
  ASSERT_EQ(filigree_watcher_frame_info(polled, &watched_info), FILIGREE_OK);
  EXPECT_GE(watched_info.frames_received, 1u);
  EXPECT_LE(max_difference(watched, frame), info.max_error + watched_info.max_error + 1e-7 * diagonal_);
  EXPECT_EQ(filigree_watcher_wait(polled, 0), FILIGREE_DEADLINE_EXCEEDED);  // still watching

  // The callback watcher got frames of the right size, and could not close
  // itself from its callback; it cannot be polled.
  {
    std::unique_lock lock(state.mutex);
    EXPECT_TRUE(state.changed.wait_for(lock, std::chrono::seconds(30), [&] { return state.frames > 0; }));
  }
  EXPECT_EQ(filigree_watcher_wait_frame(called, 0), FILIGREE_FAILED_PRECONDITION);
  EXPECT_EQ(state.close_from_callback.load(), FILIGREE_ERROR_WRONG_THREAD);
  if (state.float_count != 0) {
    EXPECT_EQ(state.float_count.load(), 3 * n_);
  }
  EXPECT_EQ(filigree_watcher_poll(called, watched.data(), watched.size(), nullptr, nullptr, nullptr),
            FILIGREE_FAILED_PRECONDITION);
  EXPECT_EQ(filigree_watcher_close(called), FILIGREE_OK) << filigree_watcher_last_error(called);
  EXPECT_EQ(filigree_watcher_free(called), FILIGREE_OK);

  // Handles go in any order: the client handle first, the streams go on.
  EXPECT_EQ(filigree_client_free(client_), FILIGREE_OK);
  client_ = nullptr;
  std::vector<float> pose = bend(-20.0);
  ASSERT_EQ(filigree_driver_send_positions(driver, 4, pose.data(), pose.size()), FILIGREE_OK);
  poll_until(driver, 4, frame);

  // Closing the session ends every stream: the watcher's wait says so and
  // the driver's polls and sends report it.
  ASSERT_EQ(filigree_close_session(session_, nullptr), FILIGREE_OK) << filigree_session_last_error(session_);
  EXPECT_EQ(filigree_watcher_wait(polled, 30000), FILIGREE_OK) << filigree_watcher_last_error(polled);
  int rc = FILIGREE_OK;
  while (rc == FILIGREE_OK) {  // frames still on their way, then the end
    rc = filigree_driver_wait_frame(driver, 30000);
    if (rc == FILIGREE_OK) rc = filigree_driver_poll(driver, frame.data(), frame.size(), nullptr, nullptr, nullptr);
  }
  EXPECT_NE(rc, FILIGREE_DEADLINE_EXCEEDED);
  EXPECT_EQ(filigree_driver_poll(driver, frame.data(), frame.size(), nullptr, nullptr, nullptr), rc);
  EXPECT_FALSE(std::string(filigree_driver_last_error(driver)).empty());
  EXPECT_NE(filigree_driver_send_positions(driver, 5, pose.data(), pose.size()), FILIGREE_OK);
  filigree_driver_close(driver);
  EXPECT_EQ(filigree_driver_free(driver), FILIGREE_OK);
  EXPECT_EQ(filigree_watcher_free(polled), FILIGREE_OK);
}

// Handles, the threshold and who changed what, as a participant's tools see them.
TEST_F(CApiServer, HandlesThresholdAndChangesOfParticipants) {
  upload();
  filigree_watcher* watcher = nullptr;
  ASSERT_EQ(filigree_watcher_open(session_, nullptr, 0, nullptr, nullptr, &watcher), FILIGREE_OK) << last_error();
  filigree_driver* driver = nullptr;
  ASSERT_EQ(filigree_driver_open(session_, nullptr, "alice", &driver), FILIGREE_OK) << last_error();
  std::vector<float> frame(3 * n_), watched(3 * n_);
  uint64_t version = 0;

  // Waits for and polls the watcher's frames until one reaches `at_least`.
  const auto watch_until = [&](uint64_t at_least) {
    while (version < at_least) {
      ASSERT_EQ(filigree_watcher_wait_frame(watcher, 30000), FILIGREE_OK) << filigree_watcher_last_error(watcher);
      ASSERT_EQ(filigree_watcher_poll(watcher, watched.data(), watched.size(), &version, nullptr, nullptr),
                FILIGREE_OK);
    }
  };

  // Alice's partial pose: a tenth of the base lifted. The changes say so.
  const std::size_t moved = std::max<std::size_t>(m_ / 10, 1);
  std::vector<uint32_t> indices(moved);
  std::vector<float> lifted(3 * moved);
  for (std::size_t k = 0; k < moved; ++k) {
    indices[k] = static_cast<uint32_t>(k);
    for (int c = 0; c < 3; ++c) lifted[3 * k + c] = base_[3 * k + c] + (c == 1 ? 0.05f * float(diagonal_) : 0.0f);
  }
  ASSERT_EQ(filigree_driver_send_partial(driver, 7, indices.data(), indices.size(), lifted.data(), lifted.size()),
            FILIGREE_OK);
  filigree_frame_info info = poll_until(driver, 7, frame);
  EXPECT_EQ(string_from(filigree_driver_changes, driver), "alice\t7\t" + std::to_string(moved) + "\n");
  watch_until(info.version);
  EXPECT_EQ(string_from(filigree_watcher_changes, watcher), "alice\t7\t" + std::to_string(moved) + "\n");
  EXPECT_EQ(filigree_watcher_wait_frame(watcher, 0), FILIGREE_DEADLINE_EXCEEDED);  // nothing newer yet

  // Bob's handle: a vertex far from alice's pull goes a tenth of the diagonal
  // along x; the frame brings it most of the way there.
  uint32_t far = 0;
  for (uint32_t v = 0; v < n_; ++v)
    if (rest_[3 * v] > rest_[3 * far]) far = v;
  const float target[3] = {watched[3 * far] + 0.1f * float(diagonal_), watched[3 * far + 1], watched[3 * far + 2]};
  uint32_t in_session = 0;
  ASSERT_EQ(filigree_set_handles(session_, nullptr, "bob", &far, 1, target, 3, &in_session), FILIGREE_OK)
      << filigree_session_last_error(session_);
  EXPECT_EQ(in_session, 1u);
  const float before = watched[3 * far];
  watch_until(version + 1);
  EXPECT_GT(watched[3 * far] - before, 0.05f * float(diagonal_)) << "the handle's vertex moved toward its target";
  EXPECT_NE(string_from(filigree_watcher_changes, watcher).find("bob\t"), std::string::npos);

  // Wrong sizes and indices are refused here, with what is wrong.
  EXPECT_EQ(filigree_set_handles(session_, nullptr, "bob", &far, 1, target, 2, nullptr), FILIGREE_INVALID_ARGUMENT);
  const uint32_t outside = static_cast<uint32_t>(n_);
  EXPECT_EQ(filigree_set_handles(session_, nullptr, "bob", &outside, 1, target, 3, nullptr),
            FILIGREE_INVALID_ARGUMENT);
  EXPECT_NE(std::string(filigree_session_last_error(session_)).find("out of range"), std::string::npos);
  EXPECT_EQ(filigree_set_handles(session_, nullptr, "bob", nullptr, 1, target, 3, nullptr),
            FILIGREE_ERROR_NULL_ARGUMENT);

  // The threshold: set, checked, and refused to a viewer.
  EXPECT_EQ(filigree_set_threshold(session_, nullptr, 0.5, 0), FILIGREE_OK) << filigree_session_last_error(session_);
  EXPECT_EQ(filigree_set_threshold(session_, nullptr, -1.0, 0), FILIGREE_INVALID_ARGUMENT);
  EXPECT_EQ(filigree_set_threshold(session_, nullptr, std::nan(""), 0), FILIGREE_INVALID_ARGUMENT);
  const std::string viewer = string_of(filigree_session_viewer_token);
  EXPECT_EQ(filigree_set_threshold(session_, viewer.c_str(), 0.5, 0), FILIGREE_PERMISSION_DENIED);
  EXPECT_EQ(filigree_set_handles(session_, viewer.c_str(), "eve", &far, 1, target, 3, nullptr),
            FILIGREE_PERMISSION_DENIED);

  // Removing bob's handles: an empty set.
  ASSERT_EQ(filigree_set_handles(session_, nullptr, "bob", nullptr, 0, nullptr, 0, &in_session), FILIGREE_OK);
  EXPECT_EQ(in_session, 0u);

  EXPECT_EQ(filigree_driver_close(driver), FILIGREE_OK) << filigree_driver_last_error(driver);
  EXPECT_EQ(filigree_driver_free(driver), FILIGREE_OK);
  EXPECT_EQ(filigree_watcher_free(watcher), FILIGREE_OK);
}

// ---------------------------------------------------------------- levels of detail

// A watcher (at a level or at full detail) and its latest polled frame, with
// the level that frame is at.
struct LevelWatch {
  explicit LevelWatch(std::size_t session_vertices) : n(session_vertices) {}
  filigree_watcher* watcher = nullptr;
  std::size_t n = 0;             // the session's vertex count
  std::vector<float> positions;  // 3 per vertex of the level, as polled
  std::size_t vertex_count = 0;  // filigree_watcher_level_vertex_count after the poll
  std::vector<uint32_t> ids, faces;
  filigree_frame_info info{};
  bool polled = false;

  // Polls until its frame's version is at least `version` and (unless 0)
  // its level has `vertices` vertices.
  void poll_until(uint64_t version, std::size_t vertices = 0) {
    std::vector<float> buffer(3 * n);  // 3·n always fits
    uint64_t at = 0;
    int updated = 0;
    while (!polled || info.version < version || (vertices != 0 && vertex_count != vertices)) {
      ASSERT_EQ(filigree_watcher_wait_frame(watcher, 30000), FILIGREE_OK)
          << filigree_watcher_last_error(watcher) << " (waiting for version " << version << " at " << vertices << ")";
      ASSERT_EQ(filigree_watcher_poll(watcher, buffer.data(), buffer.size(), &at, nullptr, &updated), FILIGREE_OK)
          << filigree_watcher_last_error(watcher);
      ASSERT_EQ(updated, 1);
      ASSERT_EQ(filigree_watcher_level_vertex_count(watcher, &vertex_count), FILIGREE_OK);
      ASSERT_EQ(filigree_watcher_frame_info(watcher, &info), FILIGREE_OK);
      ASSERT_EQ(info.version, at);
      positions.assign(buffer.begin(), buffer.begin() + 3 * vertex_count);
      ids = array(filigree_watcher_level_original_ids);
      faces = array(filigree_watcher_level_faces);
      polled = true;
    }
  }
  std::vector<uint32_t> array(int (*get)(const filigree_watcher*, uint32_t*, size_t, size_t*)) const {
    size_t required = 0;
    const int rc = get(watcher, nullptr, 0, &required);  // the size query
    EXPECT_EQ(rc, required == 0 ? FILIGREE_OK : FILIGREE_ERROR_BUFFER_TOO_SMALL);
    std::vector<uint32_t> out(required);
    EXPECT_EQ(get(watcher, out.data(), out.size(), &required), FILIGREE_OK);
    EXPECT_EQ(required, out.size());
    return out;
  }
};

// Polls `level` (at `vertices`, unless 0) and `full` until both show one
// version, at least `version`: a new level makes the session compute a
// frame for it, so a later frame may follow the one a pose asked for.
void poll_to_one_version(LevelWatch& level, LevelWatch& full, uint64_t version, std::size_t vertices = 0) {
  level.poll_until(version, vertices);
  if (::testing::Test::HasFatalFailure()) return;
  full.poll_until(level.info.version);
  while (!::testing::Test::HasFatalFailure() && level.info.version != full.info.version) {
    if (level.info.version < full.info.version) level.poll_until(full.info.version, vertices);
    else full.poll_until(level.info.version);
  }
}

// Every level vertex where the full frame of the same version has its
// session vertex, within both frames' errors; and the pose moved them.
void expect_at_full_positions(const LevelWatch& level, const LevelWatch& full, const std::vector<float>& rest) {
  ASSERT_EQ(level.info.version, full.info.version);
  ASSERT_EQ(full.vertex_count, full.n);
  const bool full_detail = level.vertex_count == level.n;
  ASSERT_EQ(level.ids.size(), full_detail ? 0u : level.vertex_count);
  ASSERT_EQ(level.positions.size(), 3 * level.vertex_count);
  double worst = 0.0, moved = 0.0;
  for (std::size_t i = 0; i < level.vertex_count; ++i) {
    const std::size_t id = full_detail ? i : level.ids[i];
    for (int c = 0; c < 3; ++c) {
      worst = std::max(worst, double(std::fabs(level.positions[3 * i + c] - full.positions[3 * id + c])));
      moved = std::max(moved, double(std::fabs(full.positions[3 * id + c] - rest[3 * id + c])));
    }
  }
  const double tolerance = double(level.info.max_error) + double(full.info.max_error) + 1e-6;
  EXPECT_LE(worst, tolerance) << "level vertices away from their place in the full frame";
  EXPECT_GT(moved, 100 * tolerance) << "the pose moved nothing: the comparison proves nothing";
}

struct LevelCallbackState {
  std::mutex mutex;
  std::condition_variable changed;
  std::atomic<filigree_watcher*> watcher{nullptr};
  uint64_t version = 0;
  std::size_t float_count = 0, level_vertex_count = 0;  // of the latest frame handed over
};

void on_level_frame(const float*, size_t float_count, uint64_t version, void* user) {
  auto* state = static_cast<LevelCallbackState*>(user);
  size_t k = 0;
  if (filigree_watcher* w = state->watcher.load()) filigree_watcher_level_vertex_count(w, &k);
  std::lock_guard lock(state->mutex);
  state->version = version;
  state->float_count = float_count;
  state->level_vertex_count = k;
  state->changed.notify_all();
}

TEST_F(CApiServer, WatchersAtABudgetGetTheirLevelsFramesOfTheFullFramesPositions) {
  upload();
  ASSERT_EQ(n_, 1839u);
  ASSERT_EQ(m_, 150u);
  // Budgets round down to a power of two; the base below its size, the full
  // mesh at or above it.
  const std::vector<std::pair<uint32_t, std::size_t>> cases = {
      {1, 150}, {200, 150}, {300, 256}, {1000, 512}, {1838, 1024}, {1839, 1839}, {100000, 1839}};
  std::vector<LevelWatch> watches(cases.size(), LevelWatch(n_));
  for (std::size_t i = 0; i < cases.size(); ++i) {
    const filigree_watch_options options{0, cases[i].first};
    ASSERT_EQ(filigree_watcher_open_with(session_, nullptr, &options, nullptr, nullptr, &watches[i].watcher), FILIGREE_OK)
        << last_error();
  }
  LevelWatch full(n_);
  ASSERT_EQ(filigree_watcher_open_with(session_, nullptr, nullptr, nullptr, nullptr, &full.watcher), FILIGREE_OK);
  LevelCallbackState state;
  filigree_watcher* called = nullptr;
  const filigree_watch_options at_300{0, 300};
  ASSERT_EQ(filigree_watcher_open_with(session_, nullptr, &at_300, on_level_frame, &state, &called), FILIGREE_OK);
  state.watcher = called;

  filigree_driver* driver = nullptr;
  ASSERT_EQ(filigree_driver_open(session_, nullptr, "full", &driver), FILIGREE_OK) << last_error();
  const std::vector<float> bent = bend(45.0);
  ASSERT_EQ(filigree_driver_send_positions(driver, 1, bent.data(), bent.size()), FILIGREE_OK);
  std::vector<float> frame(3 * n_);
  const uint64_t posed = poll_until(driver, 1, frame).version;

  for (std::size_t i = 0; i < cases.size(); ++i) {
    SCOPED_TRACE("budget " + std::to_string(cases[i].first));
    LevelWatch& w = watches[i];
    poll_to_one_version(w, full, posed);
    if (::testing::Test::HasFatalFailure()) return;
    EXPECT_EQ(w.vertex_count, cases[i].second);
    if (cases[i].second == n_) {
      EXPECT_TRUE(w.ids.empty() && w.faces.empty()) << "full detail is the rest mesh itself";
    } else {
      ASSERT_EQ(w.ids.size(), cases[i].second);
      EXPECT_TRUE(std::adjacent_find(w.ids.begin(), w.ids.end(), std::greater_equal<>()) == w.ids.end())
          << "ids must ascend";
      EXPECT_LT(w.ids.back(), n_);
      ASSERT_FALSE(w.faces.empty());
      EXPECT_EQ(w.faces.size() % 3, 0u);
      EXPECT_LT(*std::max_element(w.faces.begin(), w.faces.end()), cases[i].second);
    }
    expect_at_full_positions(w, full, rest_);
  }

  // At a level a poll needs 3·k floats, not 3·n.
  LevelWatch& at_256 = watches[2];
  ASSERT_EQ(at_256.vertex_count, 256u);
  ASSERT_EQ(filigree_driver_send_positions(driver, 2, base_.data(), base_.size()), FILIGREE_OK);
  const uint64_t second = poll_until(driver, 2, frame).version;
  ASSERT_EQ(filigree_watcher_wait_frame(at_256.watcher, 30000), FILIGREE_OK);
  std::vector<float> small(3 * 256);
  EXPECT_EQ(filigree_watcher_poll(at_256.watcher, small.data(), small.size() - 1, nullptr, nullptr, nullptr),
            FILIGREE_ERROR_BUFFER_TOO_SMALL);
  EXPECT_NE(std::string(filigree_watcher_last_error(at_256.watcher)).find("768"), std::string::npos)
      << filigree_watcher_last_error(at_256.watcher);
  int updated = 0;
  EXPECT_EQ(filigree_watcher_poll(at_256.watcher, small.data(), small.size(), nullptr, nullptr, &updated), FILIGREE_OK)
      << filigree_watcher_last_error(at_256.watcher);
  EXPECT_EQ(updated, 1);

  // The callback gets 3·k floats, and the level it asks for is theirs (of
  // a frame handed over once it knew its watcher).
  {
    std::unique_lock lock(state.mutex);
    ASSERT_TRUE(state.changed.wait_for(lock, std::chrono::seconds(30), [&] { return state.version >= second; }));
    EXPECT_EQ(state.float_count, 3u * 256);
    EXPECT_EQ(state.level_vertex_count, 256u);
  }
  EXPECT_EQ(filigree_watcher_free(called), FILIGREE_OK);
  EXPECT_EQ(filigree_driver_close(driver), FILIGREE_OK);
  EXPECT_EQ(filigree_driver_free(driver), FILIGREE_OK);
  EXPECT_EQ(filigree_watcher_free(full.watcher), FILIGREE_OK);
  for (LevelWatch& w : watches) EXPECT_EQ(filigree_watcher_free(w.watcher), FILIGREE_OK);
}

TEST_F(CApiServer, SetDetailMovesAWatcherToAnotherLevelMidStream) {
  upload();
  LevelWatch w(n_), full(n_);
  const filigree_watch_options options{0, 300};
  ASSERT_EQ(filigree_watcher_open_with(session_, nullptr, &options, nullptr, nullptr, &w.watcher), FILIGREE_OK)
      << last_error();
  ASSERT_EQ(filigree_watcher_open(session_, nullptr, 0, nullptr, nullptr, &full.watcher), FILIGREE_OK);
  // At once after the open: it waits for the stream's level, then switches.
  uint32_t k = 0;
  ASSERT_EQ(filigree_watcher_set_detail(w.watcher, 1000, &k), FILIGREE_OK) << filigree_watcher_last_error(w.watcher);
  EXPECT_EQ(k, 512u);
  w.poll_until(0, 512);  // with no pose sent
  if (::testing::Test::HasFatalFailure()) return;
  EXPECT_EQ(w.ids.size(), 512u);

  filigree_driver* driver = nullptr;
  ASSERT_EQ(filigree_driver_open(session_, nullptr, "full", &driver), FILIGREE_OK) << last_error();
  std::vector<float> frame(3 * n_);
  std::vector<float> pose = bend(35.0);
  ASSERT_EQ(filigree_driver_send_positions(driver, 1, pose.data(), pose.size()), FILIGREE_OK);
  poll_to_one_version(w, full, poll_until(driver, 1, frame).version, 512);
  expect_at_full_positions(w, full, rest_);

  // Down to the base, and a pose at it.
  ASSERT_EQ(filigree_watcher_set_detail(w.watcher, 1, &k), FILIGREE_OK) << filigree_watcher_last_error(w.watcher);
  EXPECT_EQ(k, m_);
  pose = bend(-30.0);
  ASSERT_EQ(filigree_driver_send_positions(driver, 2, pose.data(), pose.size()), FILIGREE_OK);
  poll_to_one_version(w, full, poll_until(driver, 2, frame).version, m_);
  EXPECT_EQ(w.ids.size(), m_);
  expect_at_full_positions(w, full, rest_);

  // Up to full detail: the rest mesh's frames, no ids or faces.
  ASSERT_EQ(filigree_watcher_set_detail(w.watcher, 100000, nullptr), FILIGREE_OK);
  poll_to_one_version(w, full, full.info.version, n_);
  EXPECT_TRUE(w.ids.empty() && w.faces.empty());
  expect_at_full_positions(w, full, rest_);

  // Refusals: a budget of 0, a watcher opened at full detail.
  EXPECT_EQ(filigree_watcher_set_detail(w.watcher, 0, &k), FILIGREE_INVALID_ARGUMENT);
  EXPECT_EQ(filigree_watcher_set_detail(full.watcher, 512, &k), FILIGREE_FAILED_PRECONDITION);
  EXPECT_NE(std::string(filigree_watcher_last_error(full.watcher)).find("full detail"), std::string::npos)
      << filigree_watcher_last_error(full.watcher);
  EXPECT_EQ(filigree_watcher_set_detail(nullptr, 512, &k), FILIGREE_ERROR_INVALID_HANDLE);
  EXPECT_EQ(filigree_watcher_level_vertex_count(w.watcher, nullptr), FILIGREE_ERROR_NULL_ARGUMENT);
  EXPECT_EQ(filigree_driver_close(driver), FILIGREE_OK);
  EXPECT_EQ(filigree_driver_free(driver), FILIGREE_OK);
  EXPECT_EQ(filigree_watcher_close(w.watcher), FILIGREE_OK) << filigree_watcher_last_error(w.watcher);
  EXPECT_EQ(filigree_watcher_free(w.watcher), FILIGREE_OK);
  EXPECT_EQ(filigree_watcher_free(full.watcher), FILIGREE_OK);
}

}  // namespace
