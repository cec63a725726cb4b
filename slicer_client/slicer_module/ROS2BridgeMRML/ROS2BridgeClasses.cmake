# SlicerROS2's MRML node classes, as C++ classes the scene knows (GetNodesByClass, IsA,
# saving and reopening by tag). They hold no ROS: the ROS2Bridge module's Python gives each
# the reference's methods (ROS2BridgeLib/scene_nodes.py). The list follows SlicerROS2's own
# MRML/*DefaultNodes.h and its MRML/CMakeLists.txt's generated nodes; a message or service
# outside it gets its kind's base class (vtkMRMLROS2SubscriberNode...).
# Each entry: CLASS BASE TAG. Bases come before the classes derived from them.
set(ROS2BRIDGE_MRML_CLASSES
  "vtkMRMLROS2NodeNode vtkMRMLNode ROS2Node"
  "vtkMRMLROS2SubscriberNode vtkMRMLNode ROS2Subscriber"
  "vtkMRMLROS2PublisherNode vtkMRMLNode ROS2Publisher"
  "vtkMRMLROS2ParameterNode vtkMRMLNode ROS2Parameter"
  "vtkMRMLROS2Tf2BroadcasterNode vtkMRMLNode ROS2Tf2Broadcaster"
  "vtkMRMLROS2Tf2LookupNode vtkMRMLLinearTransformNode ROS2Tf2Lookup"
  "vtkMRMLROS2RobotNode vtkMRMLNode ROS2Robot"
  "vtkMRMLROS2ServiceClientNode vtkMRMLNode ROS2ServiceClient"
  "vtkMRMLROS2MarkerSubscriberNode vtkMRMLNode ROS2MarkerSubscriber"
  "vtkMRMLROS2ActionClientNode vtkMRMLNode ROS2ActionClient"
  )
foreach(name Empty String Bool Int Double IntArray DoubleArray IntTable DoubleTable Pose
    Transform Wrench UInt8Image PointCloud PoseStamped TransformStamped WrenchStamped Joy
    JointState PoseArray)
  list(APPEND ROS2BRIDGE_MRML_CLASSES
    "vtkMRMLROS2Subscriber${name}Node vtkMRMLROS2SubscriberNode ROS2Subscriber${name}")
endforeach()
foreach(name Empty String Bool Int Double IntArray DoubleArray IntTable DoubleTable Pose
    Wrench UInt8Image PointCloud PoseStamped TransformStamped WrenchStamped Joy JointState
    PoseArray)
  list(APPEND ROS2BRIDGE_MRML_CLASSES
    "vtkMRMLROS2Publisher${name}Node vtkMRMLROS2PublisherNode ROS2Publisher${name}")
endforeach()
foreach(name SetBoolString Burst GetRate IsPaused Pause Play PlayNext Resume Seek SetRate
    Snapshot SplitBagfile Stop TogglePaused GetPositionFK GetPositionIK GetCartesianPath Spawn)
  list(APPEND ROS2BRIDGE_MRML_CLASSES
    "vtkMRMLROS2ServiceClient${name}Node vtkMRMLROS2ServiceClientNode ROS2ServiceClient${name}")
endforeach()

# ros2bridge_generate_mrml_classes(DIR HEADERS_VAR SOURCES_VAR): one header and one source per
# class in DIR, from the templates beside this file.
function(ros2bridge_generate_mrml_classes dir headers_var sources_var)
  set(headers "")
  set(sources "")
  foreach(entry IN LISTS ROS2BRIDGE_MRML_CLASSES)
    string(REPLACE " " ";" fields "${entry}")
    list(GET fields 0 CLASS)
    list(GET fields 1 BASE)
    list(GET fields 2 TAG)
    configure_file(${ROS2BRIDGE_MRML_TEMPLATES}/vtkMRMLROS2Class.h.in ${dir}/${CLASS}.h @ONLY)
    configure_file(${ROS2BRIDGE_MRML_TEMPLATES}/vtkMRMLROS2Class.cxx.in ${dir}/${CLASS}.cxx @ONLY)
    list(APPEND headers ${dir}/${CLASS}.h)
    list(APPEND sources ${dir}/${CLASS}.cxx)
  endforeach()
  set(${headers_var} ${headers} PARENT_SCOPE)
  set(${sources_var} ${sources} PARENT_SCOPE)
endfunction()
set(ROS2BRIDGE_MRML_TEMPLATES ${CMAKE_CURRENT_LIST_DIR})
