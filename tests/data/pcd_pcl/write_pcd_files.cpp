#include <pcl/io/pcd_io.h>
#include <pcl/point_types.h>
#include <cmath>
int main() {
  pcl::PointCloud<pcl::PointXYZRGBNormal> a; pcl::PointCloud<pcl::PointXYZI> b; pcl::PointCloud<pcl::PointXYZRGBL> c;
  for (int i = 0; i < 12; ++i) {
    pcl::PointXYZRGBNormal p; p.x = 0.1f * i; p.y = std::sin(0.3f * i); p.z = -1.5f + i; p.r = 10 * i; p.g = 255 - 7 * i; p.b = 3 * i; p.a = 255;
    p.normal_x = 0; p.normal_y = std::cos(0.2f * i); p.normal_z = std::sin(0.2f * i); p.curvature = 0.01f * i; a.push_back(p);
    pcl::PointXYZI q; q.x = p.x; q.y = p.y; q.z = p.z; q.intensity = 100.5f - i; b.push_back(q);
    pcl::PointXYZRGBL r; r.x = p.x; r.y = p.y; r.z = p.z; r.r = p.r; r.g = p.g; r.b = p.b; r.a = 255; r.label = 1000 + 7 * i; c.push_back(r);
  }
  a.points[3].x = std::nanf(""); a.points[3].y = std::nanf(""); a.points[3].z = std::nanf(""); a.is_dense = false;
  pcl::PCDWriter w;
  w.writeASCII("xyzrgbnormal_ascii.pcd", a); w.writeBinary("xyzrgbnormal_binary.pcd", a); w.writeBinaryCompressed("xyzrgbnormal_compressed.pcd", a);
  w.writeASCII("xyzi_ascii.pcd", b); w.writeBinary("xyzrgbl_binary.pcd", c); w.writeBinaryCompressed("xyzrgbl_compressed.pcd", c);
  return 0;
}
