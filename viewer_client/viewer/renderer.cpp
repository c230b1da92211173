#include "viewer_client/viewer/renderer.hpp"

#include <vtkActor.h>
#include <vtkCallbackCommand.h>
#include <vtkCamera.h>
#include <vtkCellData.h>
#include <vtkCellArray.h>
#include <vtkColorTransferFunction.h>
#include <vtkCoordinate.h>
#include <vtkCutter.h>
#include <vtkFloatArray.h>
#include <vtkImageActor.h>
#include <vtkImageData.h>
#include <vtkImageMapToColors.h>
#include <vtkImageMapper3D.h>
#include <vtkInteractorStyleTrackballCamera.h>
#include <vtkLineSource.h>
#include <vtkLookupTable.h>
#include <vtkNew.h>
#include <vtkPNGWriter.h>
#include <vtkPiecewiseFunction.h>
#include <vtkPlane.h>
#include <vtkPointData.h>
#include <vtkPoints.h>
#include <vtkPolyData.h>
#include <vtkPolyDataMapper.h>
#include <vtkPolyDataNormals.h>
#include <vtkProperty.h>
#include <vtkRenderWindow.h>
#include <vtkRenderWindowInteractor.h>
#include <vtkRenderer.h>
#include <vtkSmartPointer.h>
#include <vtkSmartVolumeMapper.h>
#include <vtkSphereSource.h>
#include <vtkTextActor.h>
#include <vtkTextProperty.h>
#include <vtkTubeFilter.h>
#include <vtkUnsignedCharArray.h>
#include <vtkVolume.h>
#include <vtkVolumeProperty.h>
#include <vtkWindowToImageFilter.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <map>
#include <stdexcept>

namespace neurosim::viewer {

namespace {

// Surface looks: brain translucent so slices, artery and the volume stay visible.
constexpr double kBrainColour[3] = {0.92, 0.76, 0.68};
constexpr double kArteryColour[3] = {0.85, 0.12, 0.10};
constexpr double kBackground3d[3] = {0.08, 0.09, 0.12};
// Rigid meshes (the skull): bone; translucent in SkullMode::Transparent.
constexpr double kBoneColour[3] = {0.89, 0.85, 0.72};
constexpr double kBoneTransparentOpacity = 0.3;
// Region colours (by region index; cycled beyond the table): cerebrum, cerebellum, other, ...
constexpr unsigned char kRegionColours[][3] = {
    {235, 190, 170}, {90, 160, 230}, {150, 150, 150}, {120, 200, 120},
    {230, 200, 80},  {190, 120, 220}, {240, 140, 60}, {80, 200, 200}};

// Half-height of the 2D slice views, unit m.
constexpr double kSliceViewHalfHeightM = 0.06;

struct SurfaceActor {
  std::string mesh_id;
  bool rigid = false;
  vtkSmartPointer<vtkPolyData> poly;
  vtkSmartPointer<vtkPolyDataNormals> normals;
  vtkSmartPointer<vtkActor> actor;
  // Navigation: where the deformed surface cuts each slice plane, drawn in the 2D views.
  std::array<vtkSmartPointer<vtkPlane>, 3> planes;
  std::array<vtkSmartPointer<vtkActor>, 3> contours;
  std::uint64_t u_version = ~std::uint64_t{0};
};

struct ToolActor {
  vtkSmartPointer<vtkSphereSource> tip;
  vtkSmartPointer<vtkLineSource> line;
  vtkSmartPointer<vtkTubeFilter> tube;
  std::vector<vtkSmartPointer<vtkActor>> actors;  // tip + shaft, in every renderer
};

struct SliceView {
  vtkSmartPointer<vtkImageData> image;
  vtkSmartPointer<vtkFloatArray> values;
  vtkSmartPointer<vtkImageMapToColors> colours3d;  // transparent outside the head
  vtkSmartPointer<vtkImageMapToColors> colours2d;  // opaque
  vtkSmartPointer<vtkImageActor> actor3d;
  vtkSmartPointer<vtkImageActor> actor2d;
  vtkSmartPointer<vtkTextActor> label;
};

vtkSmartPointer<vtkLookupTable> grey_table(float lo, float hi, bool transparent_background) {
  auto t = vtkSmartPointer<vtkLookupTable>::New();
  t->SetNumberOfTableValues(256);
  t->SetRange(lo, hi);
  for (int i = 0; i < 256; ++i) {
    const double v = i / 255.0;
    t->SetTableValue(i, v, v, v, transparent_background && i < 8 ? 0.0 : 1.0);
  }
  t->Build();
  return t;
}

// The last rendered frame of `window` (RGB, back buffer, no re-render) into `grab`.
void grab_frame(vtkRenderWindow* window, vtkWindowToImageFilter* grab) {
  grab->SetInput(window);
  grab->SetInputBufferTypeToRGB();
  grab->ReadFrontBufferOff();
  grab->ShouldRerenderOff();
  grab->Update();
}

}  // namespace

struct SceneRenderer::Impl {
  RenderOptions opt;
  vtkNew<vtkRenderWindow> window;
  vtkSmartPointer<vtkRenderer> view3d;
  std::array<vtkSmartPointer<vtkRenderer>, 3> view2d;  // axial, coronal, sagittal slots
  std::vector<SurfaceActor> surfaces;
  std::map<std::string, ToolActor> tools;
  std::array<SliceView, 3> slices;
  bool slices_built = false;
  float range_lo = 0, range_hi = 1;
  vtkSmartPointer<vtkImageData> volume_image;
  vtkSmartPointer<vtkFloatArray> volume_values;
  vtkSmartPointer<vtkSmartVolumeMapper> volume_mapper;
  vtkSmartPointer<vtkVolume> volume;
  vtkNew<vtkTextActor> status;
  bool camera_placed = false;

  // Rigid surfaces and their slice contours after opt.skull.
  void apply_skull() {
    for (auto& s : surfaces) {
      if (!s.rigid) continue;
      const bool visible = opt.skull != SkullMode::Hidden;
      s.actor->SetVisibility(visible ? 1 : 0);
      s.actor->GetProperty()->SetOpacity(
          opt.skull == SkullMode::Transparent ? kBoneTransparentOpacity : 1.0);
      for (auto& c : s.contours)
        if (c) c->SetVisibility(visible ? 1 : 0);
    }
  }

  std::vector<vtkRenderer*> renderers() const {
    std::vector<vtkRenderer*> r{view3d.Get()};
    for (const auto& v : view2d)
      if (v) r.push_back(v.Get());
    return r;
  }

  explicit Impl(const RenderOptions& o) : opt(o) {
    window->SetSize(o.width, o.height);
    window->SetOffScreenRendering(o.offscreen ? 1 : 0);
    window->SetMultiSamples(0);
    window->SetWindowName("neurosim-viewer");
    view3d = vtkSmartPointer<vtkRenderer>::New();
    view3d->SetBackground(kBackground3d[0], kBackground3d[1], kBackground3d[2]);
    window->AddRenderer(view3d);
    if (o.mode == Mode::Navigation) {
      view3d->SetViewport(0.0, 0.5, 0.5, 1.0);
      // Viewport slots: axial top right, coronal bottom left, sagittal bottom right.
      const double vp[3][4] = {{0.5, 0.0, 1.0, 0.5}, {0.0, 0.0, 0.5, 0.5}, {0.5, 0.5, 1.0, 1.0}};
      for (int axis = 0; axis < 3; ++axis) {
        auto r = vtkSmartPointer<vtkRenderer>::New();
        r->SetBackground(0, 0, 0);
        const double* v = vp[axis];  // axis 0 sagittal, 1 coronal, 2 axial
        r->SetViewport(v[0], v[1], v[2], v[3]);
        r->GetActiveCamera()->ParallelProjectionOn();
        window->AddRenderer(r);
        view2d[static_cast<std::size_t>(axis)] = r;
      }
    }
    status->GetTextProperty()->SetFontSize(std::max(12, o.height / 45));
    status->GetTextProperty()->SetColor(1, 1, 1);
    status->GetTextProperty()->ShadowOn();
    status->GetPositionCoordinate()->SetCoordinateSystemToNormalizedViewport();
    status->SetPosition(0.01, 0.015);
    status->SetVisibility(o.overlay ? 1 : 0);
    view3d->AddActor2D(status);
  }

  void place_camera(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi) {
    const Eigen::Vector3d c = 0.5 * (lo + hi);
    const double radius = 0.5 * (hi - lo).norm();
    // From the right, a little anterior and above (the bundled scenes are pressed on the right),
    // unless the options say where from (the demo: along the craniotomy's axis).
    const Eigen::Vector3d dir = opt.view_from.norm() > 1e-9
                                    ? opt.view_from.normalized()
                                    : Eigen::Vector3d(1.0, 0.35, 0.45).normalized();
    const double dist = radius / std::tan(0.5 * 30.0 * M_PI / 180.0) * 0.95;
    vtkCamera* cam = view3d->GetActiveCamera();
    cam->SetFocalPoint(c.x(), c.y(), c.z());
    const Eigen::Vector3d p = c + dist * dir;
    cam->SetPosition(p.x(), p.y(), p.z());
    if (std::abs(dir.z()) < 0.95)
      cam->SetViewUp(0, 0, 1);  // superior up
    else
      cam->SetViewUp(0, 1, 0);  // looking along z: anterior up
    cam->SetViewAngle(30);
    view3d->ResetCameraClippingRange();
    camera_placed = true;
  }

  void add_tool_actors(ToolActor& t) {
    for (vtkRenderer* r : renderers()) {
      auto tip_mapper = vtkSmartPointer<vtkPolyDataMapper>::New();
      tip_mapper->SetInputConnection(t.tip->GetOutputPort());
      auto tip = vtkSmartPointer<vtkActor>::New();
      tip->SetMapper(tip_mapper);
      auto shaft_mapper = vtkSmartPointer<vtkPolyDataMapper>::New();
      shaft_mapper->SetInputConnection(t.tube->GetOutputPort());
      auto shaft = vtkSmartPointer<vtkActor>::New();
      shaft->SetMapper(shaft_mapper);
      r->AddActor(tip);
      r->AddActor(shaft);
      t.actors.push_back(tip);
      t.actors.push_back(shaft);
    }
  }

  void remove_tool_actors(ToolActor& t) {
    for (vtkRenderer* r : renderers())
      for (auto& a : t.actors) r->RemoveActor(a);
    t.actors.clear();
  }

  void build_slices() {
    if (slices_built) return;
    auto lut3d = grey_table(range_lo, range_hi, true);
    auto lut2d = grey_table(range_lo, range_hi, false);
    for (std::size_t a = 0; a < 3; ++a) {
      SliceView& s = slices[a];
      s.image = vtkSmartPointer<vtkImageData>::New();
      s.values = vtkSmartPointer<vtkFloatArray>::New();
      s.image->GetPointData()->SetScalars(s.values);
      s.colours3d = vtkSmartPointer<vtkImageMapToColors>::New();
      s.colours3d->SetLookupTable(lut3d);
      s.colours3d->SetOutputFormatToRGBA();
      s.colours3d->SetInputData(s.image);
      s.colours2d = vtkSmartPointer<vtkImageMapToColors>::New();
      s.colours2d->SetLookupTable(lut2d);
      s.colours2d->SetOutputFormatToRGB();
      s.colours2d->SetInputData(s.image);
      s.actor3d = vtkSmartPointer<vtkImageActor>::New();
      s.actor3d->GetMapper()->SetInputConnection(s.colours3d->GetOutputPort());
      s.actor3d->ForceTranslucentOn();
      s.actor2d = vtkSmartPointer<vtkImageActor>::New();
      s.actor2d->GetMapper()->SetInputConnection(s.colours2d->GetOutputPort());
      s.actor2d->InterpolateOn();
      s.label = vtkSmartPointer<vtkTextActor>::New();
      s.label->GetTextProperty()->SetFontSize(std::max(11, opt.height / 50));
      s.label->GetTextProperty()->SetColor(0.9, 0.9, 0.3);
      s.label->GetTextProperty()->ShadowOn();
      s.label->GetPositionCoordinate()->SetCoordinateSystemToNormalizedViewport();
      s.label->SetPosition(0.01, 0.015);
      s.label->SetVisibility(opt.overlay ? 1 : 0);
      s.actor3d->SetVisibility(0);
      s.actor2d->SetVisibility(0);
      view3d->AddActor(s.actor3d);
      view2d[a]->AddActor(s.actor2d);
      view2d[a]->AddActor2D(s.label);
    }
    slices_built = true;
  }
};

SceneRenderer::SceneRenderer(const RenderOptions& options)
    : impl_(std::make_unique<Impl>(options)) {}
SceneRenderer::~SceneRenderer() = default;

int SceneRenderer::width() const { return impl_->window->GetSize()[0]; }
int SceneRenderer::height() const { return impl_->window->GetSize()[1]; }

void SceneRenderer::set_meshes(const ViewerState& state) {
  Impl& im = *impl_;
  for (auto& s : im.surfaces) {
    im.view3d->RemoveActor(s.actor);
    for (std::size_t a = 0; a < 3; ++a)
      if (s.contours[a]) im.view2d[a]->RemoveActor(s.contours[a]);
  }
  im.surfaces.clear();
  for (const MeshState& m : state.meshes()) {
    SurfaceActor s;
    s.mesh_id = m.id;
    s.poly = vtkSmartPointer<vtkPolyData>::New();
    vtkNew<vtkPoints> pts;
    pts->SetDataTypeToFloat();
    pts->SetNumberOfPoints(static_cast<vtkIdType>(m.rest_m.size()));
    vtkNew<vtkCellArray> tris;
    for (const auto& t : m.surface) {
      const vtkIdType ids[3] = {t[0], t[1], t[2]};
      tris->InsertNextCell(3, ids);
    }
    s.poly->SetPoints(pts);
    s.poly->SetPolys(tris);
    s.rigid = m.rigid;
    // Region colours per surface triangle (the tissue of the tetrahedron it bounds).
    const bool by_region =
        !m.rigid && im.opt.colour == ColourMode::Region && !m.region_names.empty();
    if (by_region) {
      const std::vector<int> region = surface_regions(m);
      vtkNew<vtkUnsignedCharArray> rgb;
      rgb->SetNumberOfComponents(3);
      rgb->SetName("region");
      rgb->SetNumberOfTuples(static_cast<vtkIdType>(region.size()));
      constexpr std::size_t kColours = sizeof kRegionColours / sizeof kRegionColours[0];
      for (std::size_t i = 0; i < region.size(); ++i) {
        unsigned char c[3];
        for (int k = 0; k < 3; ++k)
          c[k] = region[i] < 0
                     ? static_cast<unsigned char>(255 * kBrainColour[k])
                     : kRegionColours[static_cast<std::size_t>(region[i]) % kColours][k];
        rgb->SetTypedTuple(static_cast<vtkIdType>(i), c);
      }
      s.poly->GetCellData()->SetScalars(rgb);
    }
    s.normals = vtkSmartPointer<vtkPolyDataNormals>::New();
    s.normals->SetInputData(s.poly);
    s.normals->SplittingOff();
    s.normals->ConsistencyOff();
    s.normals->AutoOrientNormalsOff();
    auto mapper = vtkSmartPointer<vtkPolyDataMapper>::New();
    mapper->SetInputConnection(s.normals->GetOutputPort());
    if (by_region) {
      mapper->SetScalarModeToUseCellData();
      mapper->SetColorModeToDirectScalars();
      mapper->ScalarVisibilityOn();
    } else {
      mapper->ScalarVisibilityOff();
    }
    s.actor = vtkSmartPointer<vtkActor>::New();
    s.actor->SetMapper(mapper);
    // The embedded (higher priority) meshes are the vessels: opaque red; the host translucent;
    // rigid meshes bone (opacity from the skull mode).
    const bool vessel = !m.rigid && m.priority > 0;
    const double* c = m.rigid ? kBoneColour : vessel ? kArteryColour : kBrainColour;
    s.actor->GetProperty()->SetColor(c[0], c[1], c[2]);
    s.actor->GetProperty()->SetSpecular(0.2);
    if (!vessel && !m.rigid)
      s.actor->GetProperty()->SetOpacity(im.opt.mode == Mode::Navigation ? 0.45 : 0.25);
    im.view3d->AddActor(s.actor);
    if (im.opt.mode == Mode::Navigation) {
      for (std::size_t a = 0; a < 3; ++a) {
        s.planes[a] = vtkSmartPointer<vtkPlane>::New();
        double nrm[3] = {0, 0, 0};
        nrm[a] = 1;
        s.planes[a]->SetNormal(nrm);
        auto cutter = vtkSmartPointer<vtkCutter>::New();
        cutter->SetCutFunction(s.planes[a]);
        cutter->SetInputData(s.poly);
        auto cmapper = vtkSmartPointer<vtkPolyDataMapper>::New();
        cmapper->SetInputConnection(cutter->GetOutputPort());
        cmapper->ScalarVisibilityOff();
        s.contours[a] = vtkSmartPointer<vtkActor>::New();
        s.contours[a]->SetMapper(cmapper);
        const double* cc = m.rigid ? kBoneColour : nullptr;
        s.contours[a]->GetProperty()->SetColor(cc ? cc[0] : vessel ? kArteryColour[0] : 0.3,
                                               cc ? cc[1] : vessel ? kArteryColour[1] : 0.9,
                                               cc ? cc[2] : vessel ? kArteryColour[2] : 0.4);
        s.contours[a]->GetProperty()->SetLineWidth(2);
        s.contours[a]->GetProperty()->LightingOff();
        // 1 mm towards the 2D view's camera (on +axis): drawn over the slice, not in it.
        double offset[3] = {0, 0, 0};
        offset[a] = 0.001;
        s.contours[a]->SetPosition(offset);
        im.view2d[a]->AddActor(s.contours[a]);
      }
    }
    im.surfaces.push_back(s);
  }
  im.apply_skull();
  if (!im.camera_placed && !state.meshes().empty()) {
    const auto [lo, hi] = state.bounds_m();
    im.place_camera(lo, hi);
  }
}

void SceneRenderer::update(const ViewerState& state, const std::string& status) {
  Impl& im = *impl_;
  for (auto& s : im.surfaces) {
    const MeshState* m = state.mesh(s.mesh_id);
    if (m == nullptr || m->u_version == s.u_version) continue;
    vtkPoints* pts = s.poly->GetPoints();
    for (std::size_t i = 0; i < m->rest_m.size(); ++i) {
      const Eigen::Vector3d& x = m->rest_m[i];
      pts->SetPoint(static_cast<vtkIdType>(i), x.x() + m->u_m[3 * i], x.y() + m->u_m[3 * i + 1],
                    x.z() + m->u_m[3 * i + 2]);
    }
    pts->Modified();
    s.poly->Modified();
    s.u_version = m->u_version;
  }
  // Tools: one tip + shaft per station, coloured by the paper's force rule.
  for (auto it = im.tools.begin(); it != im.tools.end();) {
    if (state.tools().count(it->first) == 0) {
      im.remove_tool_actors(it->second);
      it = im.tools.erase(it);
    } else {
      ++it;
    }
  }
  for (const auto& [station, tool] : state.tools()) {
    if (!tool.has_pose) continue;
    auto found = im.tools.find(station);
    if (found == im.tools.end()) {
      ToolActor t;
      t.tip = vtkSmartPointer<vtkSphereSource>::New();
      t.tip->SetRadius(im.opt.tip_radius_m);
      t.tip->SetThetaResolution(24);
      t.tip->SetPhiResolution(16);
      t.line = vtkSmartPointer<vtkLineSource>::New();
      t.tube = vtkSmartPointer<vtkTubeFilter>::New();
      t.tube->SetInputConnection(t.line->GetOutputPort());
      t.tube->SetRadius(im.opt.shaft_radius_m);
      t.tube->SetNumberOfSides(16);
      t.tube->CappingOn();
      found = im.tools.emplace(station, t).first;
      im.add_tool_actors(found->second);
    }
    ToolActor& t = found->second;
    t.tip->SetCenter(tool.tip_m.x(), tool.tip_m.y(), tool.tip_m.z());
    const Eigen::Vector3d end = tool.tip_m + im.opt.shaft_length_m * tool.axis;
    t.line->SetPoint1(tool.tip_m.x(), tool.tip_m.y(), tool.tip_m.z());
    t.line->SetPoint2(end.x(), end.y(), end.z());
    const auto rgb = force_colour(tool.force_n.norm(), im.opt.force_unit_n);
    for (auto& a : t.actors) {
      a->GetProperty()->SetColor(rgb[0], rgb[1], rgb[2]);
      a->GetProperty()->SetAmbient(0.4);  // the rule's colour reads also on the unlit side
      a->GetProperty()->SetDiffuse(0.7);
    }
  }
  im.status->SetInput(status.c_str());
}

void SceneRenderer::set_image_range(float low, float high) {
  impl_->range_lo = low;
  impl_->range_hi = high > low ? high : low + 1;
}

void SceneRenderer::set_slices(const std::array<Slice, 3>* slices,
                               const Eigen::Vector3d& centre_m) {
  Impl& im = *impl_;
  if (im.opt.mode != Mode::Navigation) return;
  if (slices == nullptr) {
    for (auto& s : im.slices)
      if (s.actor3d) {
        s.actor3d->SetVisibility(0);
        s.actor2d->SetVisibility(0);
      }
  } else {
    im.build_slices();
    static const char* kNames[3] = {"sagittal", "coronal", "axial"};
    for (std::size_t a = 0; a < 3; ++a) {
      const Slice& sl = (*slices)[a];
      SliceView& v = im.slices[a];
      if (sl.width <= 0 || sl.height <= 0 ||
          sl.values.size() !=
              static_cast<std::size_t>(sl.width) * static_cast<std::size_t>(sl.height))
        continue;
      const int axis = sl.axis;
      const int u = axis == 0 ? 1 : 0;
      const int w = axis == 2 ? 1 : 2;
      int dims[3] = {1, 1, 1};
      double spacing[3] = {1, 1, 1};
      double origin[3] = {sl.origin_m.x(), sl.origin_m.y(), sl.origin_m.z()};
      dims[u] = sl.width;
      dims[w] = sl.height;
      spacing[u] = sl.spacing_m.x();
      spacing[w] = sl.spacing_m.y();
      origin[axis] = sl.position_m;
      int cur[3];
      v.image->GetDimensions(cur);
      if (cur[0] != dims[0] || cur[1] != dims[1] || cur[2] != dims[2]) {
        v.image->SetDimensions(dims);
        v.values->SetNumberOfTuples(static_cast<vtkIdType>(sl.values.size()));
        // A flat display extent makes the image actor show the slice in its own orientation.
        v.actor3d->SetDisplayExtent(0, dims[0] - 1, 0, dims[1] - 1, 0, dims[2] - 1);
        v.actor2d->SetDisplayExtent(0, dims[0] - 1, 0, dims[1] - 1, 0, dims[2] - 1);
      }
      v.image->SetSpacing(spacing);
      v.image->SetOrigin(origin);
      std::memcpy(v.values->GetPointer(0), sl.values.data(), sl.values.size() * sizeof(float));
      v.values->Modified();
      v.image->Modified();
      v.actor3d->SetVisibility(1);
      v.actor2d->SetVisibility(1);
      char text[96];
      std::snprintf(text, sizeof text, "%s  %c = %.1f mm", kNames[axis], "xyz"[axis],
                    sl.position_m * 1e3);
      v.label->SetInput(text);
    }
  }
  // Surface contours in the slice planes.
  for (auto& s : im.surfaces)
    for (std::size_t a = 0; a < 3; ++a) {
      if (!s.planes[a]) continue;
      Eigen::Vector3d o = centre_m;
      if (slices != nullptr && (*slices)[a].width > 0)
        o[static_cast<Eigen::Index>(a)] = (*slices)[a].position_m;
      s.planes[a]->SetOrigin(o.x(), o.y(), o.z());
    }
  // 2D cameras look along their axis at the slice point.
  for (int axis = 0; axis < 3; ++axis) {
    vtkCamera* cam = im.view2d[static_cast<std::size_t>(axis)]->GetActiveCamera();
    Eigen::Vector3d dir = Eigen::Vector3d::Zero();
    dir[axis] = 1.0;
    const Eigen::Vector3d p = centre_m + 0.5 * dir;
    cam->SetFocalPoint(centre_m.x(), centre_m.y(), centre_m.z());
    cam->SetPosition(p.x(), p.y(), p.z());
    if (axis == 2)
      cam->SetViewUp(0, 1, 0);
    else
      cam->SetViewUp(0, 0, 1);
    cam->SetParallelScale(kSliceViewHalfHeightM);
    cam->SetClippingRange(0.3, 0.7);
  }
}

void SceneRenderer::set_volume(const ImageGrid* grid) {
  Impl& im = *impl_;
  if (im.opt.mode != Mode::Observe) return;
  if (grid == nullptr || grid->values.empty()) {
    if (im.volume) im.volume->SetVisibility(0);
    return;
  }
  if (!im.volume) {
    im.volume_image = vtkSmartPointer<vtkImageData>::New();
    im.volume_values = vtkSmartPointer<vtkFloatArray>::New();
    im.volume_image->GetPointData()->SetScalars(im.volume_values);
    im.volume_mapper = vtkSmartPointer<vtkSmartVolumeMapper>::New();
    im.volume_mapper->SetInputData(im.volume_image);
    vtkNew<vtkColorTransferFunction> colour;
    const double lo = im.range_lo, hi = im.range_hi;
    colour->AddRGBPoint(lo, 0.0, 0.0, 0.0);
    colour->AddRGBPoint(lo + 0.5 * (hi - lo), 0.55, 0.45, 0.42);
    colour->AddRGBPoint(hi, 1.0, 1.0, 1.0);
    vtkNew<vtkPiecewiseFunction> opacity;
    opacity->AddPoint(lo, 0.0);
    opacity->AddPoint(lo + 0.25 * (hi - lo), 0.0);
    opacity->AddPoint(lo + 0.55 * (hi - lo), 0.03);
    opacity->AddPoint(hi, 0.25);
    auto prop = vtkSmartPointer<vtkVolumeProperty>::New();
    prop->SetColor(colour);
    prop->SetScalarOpacity(opacity);
    prop->SetInterpolationTypeToLinear();
    prop->ShadeOff();
    // Opacities are per voxel, not per metre (VTK's default unit distance is 1 scene unit).
    prop->SetScalarOpacityUnitDistance(grid->spacing_m.minCoeff());
    im.volume_mapper->InteractiveAdjustSampleDistancesOff();
    im.volume_mapper->AutoAdjustSampleDistancesOff();
    im.volume_mapper->SetSampleDistance(static_cast<float>(grid->spacing_m.minCoeff()));
    im.volume = vtkSmartPointer<vtkVolume>::New();
    im.volume->SetMapper(im.volume_mapper);
    im.volume->SetProperty(prop);
    im.view3d->AddVolume(im.volume);
  }
  int cur[3];
  im.volume_image->GetDimensions(cur);
  if (cur[0] != grid->dims[0] || cur[1] != grid->dims[1] || cur[2] != grid->dims[2]) {
    im.volume_image->SetDimensions(grid->dims[0], grid->dims[1], grid->dims[2]);
    im.volume_values->SetNumberOfTuples(static_cast<vtkIdType>(grid->values.size()));
  }
  im.volume_image->SetSpacing(grid->spacing_m.x(), grid->spacing_m.y(), grid->spacing_m.z());
  im.volume_image->SetOrigin(grid->origin_m.x(), grid->origin_m.y(), grid->origin_m.z());
  std::memcpy(im.volume_values->GetPointer(0), grid->values.data(),
              grid->values.size() * sizeof(float));
  im.volume_values->Modified();
  im.volume_image->Modified();
  im.volume->SetVisibility(1);
}

void SceneRenderer::set_volume_crop(const Eigen::Vector3d& c) {
  Impl& im = *impl_;
  if (!im.volume_mapper || !c.allFinite()) return;
  constexpr double kFar = 1e3;  // m: beyond any scene
  im.volume_mapper->SetCropping(1);
  im.volume_mapper->SetCroppingRegionPlanes(c.x(), kFar, c.y(), kFar, c.z(), kFar);
  // Regions i + 3 j + 9 k (i, j, k: below / between / above the planes): keep all but the
  // octant with i, j, k >= 1.
  int flags = 0;
  for (int k = 0; k < 3; ++k)
    for (int j = 0; j < 3; ++j)
      for (int i = 0; i < 3; ++i)
        if (i == 0 || j == 0 || k == 0) flags |= 1 << (i + 3 * j + 9 * k);
  im.volume_mapper->SetCroppingRegionFlags(flags);
}

void SceneRenderer::set_skull(SkullMode mode) {
  impl_->opt.skull = mode;
  impl_->apply_skull();
}

SkullMode SceneRenderer::skull() const { return impl_->opt.skull; }

void SceneRenderer::render() {
  impl_->view3d->ResetCameraClippingRange();
  impl_->window->Render();
}

std::vector<std::uint8_t> SceneRenderer::capture() {
  vtkNew<vtkWindowToImageFilter> grab;
  grab_frame(impl_->window, grab);
  vtkImageData* im = grab->GetOutput();
  auto* px = vtkUnsignedCharArray::SafeDownCast(im->GetPointData()->GetScalars());
  if (px == nullptr) throw std::runtime_error("viewer: could not read the rendered frame");
  const auto n = static_cast<std::size_t>(px->GetNumberOfValues());
  std::vector<std::uint8_t> out(n);
  std::memcpy(out.data(), px->GetPointer(0), n);
  return out;
}

void SceneRenderer::write_png(const std::string& path) {
  vtkNew<vtkWindowToImageFilter> grab;
  grab_frame(impl_->window, grab);
  vtkNew<vtkPNGWriter> writer;
  writer->SetFileName(path.c_str());
  writer->SetInputConnection(grab->GetOutputPort());
  writer->Write();
  if (writer->GetErrorCode() != 0)
    throw std::runtime_error(path + ": cannot write PNG frame (VTK error " +
                             std::to_string(writer->GetErrorCode()) + ")");
}

std::vector<std::uint8_t> SceneRenderer::mask_around(const Eigen::Vector3d& p, double radius_m) {
  Impl& im = *impl_;
  const int w = width(), h = height();
  std::vector<std::uint8_t> mask(static_cast<std::size_t>(w) * static_cast<std::size_t>(h), 0);
  for (vtkRenderer* r : im.renderers()) {
    auto project = [&](const Eigen::Vector3d& x) {
      r->SetWorldPoint(x.x(), x.y(), x.z(), 1.0);
      r->WorldToDisplay();
      double d[3];
      r->GetDisplayPoint(d);
      return Eigen::Vector2d(d[0], d[1]);
    };
    const Eigen::Vector2d c = project(p);
    double rad = 0;
    for (int a = 0; a < 3; ++a)
      for (double s : {-1.0, 1.0}) {
        Eigen::Vector3d q = p;
        q[a] += s * radius_m;
        rad = std::max(rad, (project(q) - c).norm());
      }
    const double* vp = r->GetViewport();
    const int x0 = static_cast<int>(vp[0] * w), x1 = static_cast<int>(vp[2] * w);
    const int y0 = static_cast<int>(vp[1] * h), y1 = static_cast<int>(vp[3] * h);
    for (int y = std::max(y0, 0); y < std::min(y1, h); ++y)
      for (int x = std::max(x0, 0); x < std::min(x1, w); ++x)
        if ((Eigen::Vector2d(x + 0.5, y + 0.5) - c).norm() <= rad)
          mask[static_cast<std::size_t>(y) * static_cast<std::size_t>(w) +
               static_cast<std::size_t>(x)] = 1;
  }
  return mask;
}

void SceneRenderer::run_interactive(const std::function<bool()>& tick, double period_s) {
  Impl& im = *impl_;
  vtkNew<vtkRenderWindowInteractor> interactor;
  vtkNew<vtkInteractorStyleTrackballCamera> style;
  interactor->SetInteractorStyle(style);
  interactor->SetRenderWindow(im.window);
  interactor->Initialize();
  struct Ctx {
    const std::function<bool()>* tick;
    vtkRenderWindowInteractor* interactor;
  } ctx{&tick, interactor.Get()};
  vtkNew<vtkCallbackCommand> cb;
  cb->SetClientData(&ctx);
  cb->SetCallback([](vtkObject*, unsigned long, void* data, void*) {
    auto* c = static_cast<Ctx*>(data);
    if (!(*c->tick)()) c->interactor->TerminateApp();
  });
  interactor->AddObserver(vtkCommand::TimerEvent, cb);
  // 'k' cycles the skull: shown -> transparent -> hidden.
  struct KeyCtx {
    SceneRenderer* self;
    vtkRenderWindowInteractor* interactor;
  } key_ctx{this, interactor.Get()};
  vtkNew<vtkCallbackCommand> key_cb;
  key_cb->SetClientData(&key_ctx);
  key_cb->SetCallback([](vtkObject*, unsigned long, void* data, void*) {
    auto* c = static_cast<KeyCtx*>(data);
    const char key = c->interactor->GetKeyCode();
    if (key != 'k' && key != 'K') return;
    c->self->set_skull(next(c->self->skull()));
    c->self->render();
  });
  interactor->AddObserver(vtkCommand::KeyPressEvent, key_cb);
  interactor->CreateRepeatingTimer(static_cast<unsigned long>(std::max(1.0, period_s * 1e3)));
  interactor->Start();
}

}  // namespace neurosim::viewer
