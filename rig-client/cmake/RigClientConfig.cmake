# CMake package config of rig-client (installed by rig-client/install.sh into
# PREFIX/lib/cmake/RigClient). find_package(RigClient) gives the imported targets
#   RigClient::rig_client         the shared library (librig_client.so) with rig_client.h/.hpp
#   RigClient::rig_client_static  the static library (librig_client.a) and the system libraries it needs
get_filename_component(_rig_client_prefix "${CMAKE_CURRENT_LIST_DIR}/../../.." ABSOLUTE)
set(RigClient_VERSION "@VERSION@")
set(RigClient_INCLUDE_DIRS "${_rig_client_prefix}/include")
find_package(Threads REQUIRED)
if(NOT TARGET RigClient::rig_client)
  add_library(RigClient::rig_client SHARED IMPORTED)
  set_target_properties(RigClient::rig_client PROPERTIES
    IMPORTED_LOCATION "${_rig_client_prefix}/lib/librig_client.so"
    IMPORTED_NO_SONAME TRUE
    INTERFACE_INCLUDE_DIRECTORIES "${_rig_client_prefix}/include")
endif()
if(NOT TARGET RigClient::rig_client_static)
  add_library(RigClient::rig_client_static STATIC IMPORTED)
  set_target_properties(RigClient::rig_client_static PROPERTIES
    IMPORTED_LOCATION "${_rig_client_prefix}/lib/librig_client.a"
    INTERFACE_INCLUDE_DIRECTORIES "${_rig_client_prefix}/include"
    INTERFACE_LINK_LIBRARIES "Threads::Threads;dl;m;rt")
endif()
unset(_rig_client_prefix)
