#pragma once
// LCM channels of the world-model service (message types in lcm_types/, package artisan).
namespace artisan::teleop {

inline constexpr const char* kSceneChannel = "ARTISAN_SCENE";                  ///< scene_snapshot_t
inline constexpr const char* kSceneDiffChannel = "ARTISAN_SCENE_DIFF";         ///< scene_diff_t
inline constexpr const char* kMeshRequestChannel = "ARTISAN_MESH_REQUEST";     ///< mesh_request_t
inline constexpr const char* kMeshChunkChannel = "ARTISAN_MESH_CHUNK";         ///< mesh_chunk_t
inline constexpr const char* kQueryChannel = "ARTISAN_QUERY";                  ///< query_t
inline constexpr const char* kQueryReplyChannel = "ARTISAN_QUERY_REPLY";       ///< query_reply_t
inline constexpr const char* kCommandChannel = "ARTISAN_COMMAND";              ///< command_t
inline constexpr const char* kCommandResultChannel = "ARTISAN_COMMAND_RESULT"; ///< command_result_t
inline constexpr const char* kEnvironmentChannel = "ARTISAN_ENVIRONMENT";      ///< environment_reading_t
inline constexpr const char* kHeartbeatChannel = "ARTISAN_HEARTBEAT";          ///< heartbeat_t
inline constexpr const char* kServiceErrorChannel = "ARTISAN_SERVICE_ERROR";   ///< service_error_t

/// Mesh data per chunk message: one UDP datagram (LCM fragments larger messages, and one lost
/// fragment would lose the whole chunk).
inline constexpr int kMeshChunkBytes = 48 * 1024;
/// Chunks a client asks for at once; it asks for the next ones when these have arrived.
inline constexpr int kMeshChunkWindow = 16;
/// Default LCM URL: multicast that never leaves the machine (ttl=0).
inline constexpr const char* kDefaultLcmUrl = "udpm://239.255.76.67:7667?ttl=0";

}  // namespace artisan::teleop
