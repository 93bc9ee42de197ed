// sdf_check: load an SDFormat file with libsdformat (the reference SDFormat parser, the one Gazebo
// uses) and report what it holds. Used by exporters/sdf.py (when built, see scripts/bootstrap.sh)
// and by tests/test_export_sdf.py: Debian bookworm packages libsdformat12 but no `gz sdf` / `ign
// sdf` command line tool (ignition-tools is not packaged), so this is the command line checker.
//
//   sdf_check FILE.sdf
//
// Parses strictly (warnings, unrecognised and deprecated elements are errors), prints every
// error on stderr, one a line, and exits 1 when there is any. Otherwise it prints one JSON object
// on stdout: the world's gravity, and per model (nested models flattened, scoped "a::b") whether
// it is static, its pose in the world, its links (mass, centre of mass in the world, whether the
// mass matrix is physically valid, collision / visual counts, camera sensors with their
// intrinsics) and its joints (type, limits, damping, friction). Exit 2: usage.
//
// Build: g++ -O1 -o sdf_check scripts/sdf_check.cc $(pkg-config --cflags --libs sdformat12)

#include <cmath>
#include <cstdio>
#include <iostream>
#include <sstream>
#include <string>

#include <sdf/sdf.hh>

namespace {

std::string Quote(const std::string &s) {
  std::ostringstream out;
  out << '"';
  for (unsigned char c : s) {
    if (c == '"' || c == '\\') {
      out << '\\' << c;
    } else if (c < 0x20) {
      char buf[8];
      std::snprintf(buf, sizeof(buf), "\\u%04x", c);
      out << buf;
    } else {
      out << c;
    }
  }
  out << '"';
  return out.str();
}

// A JSON number (null for inf / nan, which JSON cannot hold: an unlimited effort is inf).
std::string Num(double v) {
  if (!std::isfinite(v)) return "null";
  std::ostringstream out;
  out.precision(12);
  out << v;
  return out.str();
}

std::string Vec(const ignition::math::Vector3d &v) {
  return "[" + Num(v.X()) + "," + Num(v.Y()) + "," + Num(v.Z()) + "]";
}

const char *JointTypeName(sdf::JointType t) {
  switch (t) {
    case sdf::JointType::BALL: return "ball";
    case sdf::JointType::CONTINUOUS: return "continuous";
    case sdf::JointType::FIXED: return "fixed";
    case sdf::JointType::GEARBOX: return "gearbox";
    case sdf::JointType::PRISMATIC: return "prismatic";
    case sdf::JointType::REVOLUTE: return "revolute";
    case sdf::JointType::REVOLUTE2: return "revolute2";
    case sdf::JointType::SCREW: return "screw";
    case sdf::JointType::UNIVERSAL: return "universal";
    default: return "invalid";
  }
}

bool Fail(const sdf::Errors &errors, const std::string &where) {
  for (const auto &e : errors) {
    std::cerr << where << ": " << e.Message() << std::endl;
  }
  return !errors.empty();
}

void Model(const sdf::Model *model, const std::string &scope, const ignition::math::Pose3d &parent,
           bool parentStatic, std::ostringstream &out, bool &first, bool &bad) {
  const std::string name = scope.empty() ? model->Name() : scope + "::" + model->Name();
  ignition::math::Pose3d rel;
  bad |= Fail(model->SemanticPose().Resolve(rel), name + " pose");
  const ignition::math::Pose3d world = parent * rel;
  const bool isStatic = parentStatic || model->Static();
  if (!first) out << ',';
  first = false;
  out << "{\"name\":" << Quote(name) << ",\"static\":" << (isStatic ? "true" : "false")
      << ",\"position\":" << Vec(world.Pos()) << ",\"links\":[";
  for (uint64_t i = 0; i < model->LinkCount(); ++i) {
    const sdf::Link *link = model->LinkByIndex(i);
    ignition::math::Pose3d lp;
    bad |= Fail(link->SemanticPose().Resolve(lp, "__model__"), name + "::" + link->Name() + " pose");
    const auto &inertial = link->Inertial();
    const ignition::math::Pose3d com = world * lp * inertial.Pose();
    out << (i ? "," : "") << "{\"name\":" << Quote(link->Name()) << ",\"mass\":" << Num(inertial.MassMatrix().Mass())
        << ",\"com\":" << Vec(com.Pos()) << ",\"inertia_valid\":" << (inertial.MassMatrix().IsValid() ? "true" : "false")
        << ",\"collisions\":" << link->CollisionCount() << ",\"visuals\":" << link->VisualCount() << ",\"cameras\":[";
    bool firstCam = true;
    for (uint64_t s = 0; s < link->SensorCount(); ++s) {
      const sdf::Sensor *sensor = link->SensorByIndex(s);
      const sdf::Camera *cam = sensor->CameraSensor();
      if (sensor->Type() != sdf::SensorType::CAMERA || cam == nullptr) continue;
      out << (firstCam ? "" : ",") << "{\"name\":" << Quote(sensor->Name()) << ",\"horizontal_fov\":" << Num(cam->HorizontalFov().Radian())
          << ",\"width\":" << cam->ImageWidth() << ",\"height\":" << cam->ImageHeight() << ",\"fx\":" << Num(cam->LensIntrinsicsFx())
          << ",\"fy\":" << Num(cam->LensIntrinsicsFy()) << ",\"cx\":" << Num(cam->LensIntrinsicsCx()) << ",\"cy\":" << Num(cam->LensIntrinsicsCy()) << '}';
      firstCam = false;
    }
    out << "]}";
  }
  out << "],\"joints\":[";
  for (uint64_t j = 0; j < model->JointCount(); ++j) {
    const sdf::Joint *joint = model->JointByIndex(j);
    out << (j ? "," : "") << "{\"name\":" << Quote(joint->Name()) << ",\"type\":\"" << JointTypeName(joint->Type())
        << "\",\"parent\":" << Quote(joint->ParentLinkName()) << ",\"child\":" << Quote(joint->ChildLinkName());
    if (const sdf::JointAxis *axis = joint->Axis(0)) {
      out << ",\"lower\":" << Num(axis->Lower()) << ",\"upper\":" << Num(axis->Upper()) << ",\"damping\":" << Num(axis->Damping())
          << ",\"friction\":" << Num(axis->Friction()) << ",\"effort\":" << Num(axis->Effort());
    }
    out << '}';
  }
  out << "]}";
  for (uint64_t m = 0; m < model->ModelCount(); ++m) {
    Model(model->ModelByIndex(m), name, world, isStatic, out, first, bad);
  }
}

}  // namespace

int main(int argc, char **argv) {
  if (argc != 2) {
    std::cerr << "usage: sdf_check FILE.sdf" << std::endl;
    return 2;
  }
  sdf::ParserConfig config;
  config.SetWarningsPolicy(sdf::EnforcementPolicy::ERR);
  config.SetUnrecognizedElementsPolicy(sdf::EnforcementPolicy::ERR);
  config.SetDeprecatedElementsPolicy(sdf::EnforcementPolicy::ERR);
  sdf::Root root;
  if (Fail(root.Load(argv[1], config), argv[1])) return 1;
  if (root.WorldCount() != 1) {
    std::cerr << argv[1] << ": expected one <world>, found " << root.WorldCount() << std::endl;
    return 1;
  }
  const sdf::World *world = root.WorldByIndex(0);
  std::ostringstream out;
  out.precision(12);
  out << "{\"version\":" << Quote(root.Version()) << ",\"world\":" << Quote(world->Name()) << ",\"gravity\":" << Vec(world->Gravity())
      << ",\"models\":[";
  bool first = true, bad = false;
  for (uint64_t m = 0; m < world->ModelCount(); ++m) {
    Model(world->ModelByIndex(m), "", ignition::math::Pose3d::Zero, false, out, first, bad);
  }
  out << "]}";
  if (bad) return 1;
  std::cout << out.str() << std::endl;
  return 0;
}
