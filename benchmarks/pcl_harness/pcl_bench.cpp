// Times PCL's global descriptors and normal estimation on the objects of a
// file written by benchmarks/_data.py (write_objects), one object at a time
// on one thread, the way the eppf benchmarks time eppf on the same file.
//
//   pcl_bench FILE TASK [--repeats R] [--k K] [--per-object] [--out ROWS]
//
// TASK: normals (NormalEstimation, K nearest neighbors, default 20), esf,
// gasd, vfh, cvfh, cvfh_default (CVFH with PCL's defaults), ourcvfh, grsd.
// The descriptors use the normals stored in the file; normals ignores them.
// Settings are those of the PCL reference runs of the documentation: CVFH and OUR-CVFH with an EPS angle of 5
// degrees, curvature threshold 1.0 and bins not normalized (OUR-CVFH: axis
// ratio 0.8), the first signature kept; GRSD with radius 0.05; GASD, VFH and
// ESF with PCL's defaults; a k-d tree search everywhere.
//
// Prints one line, "pcl_bench TASK objects N ms_per_object BEST passes R",
// BEST the smallest over R passes of the process CPU time of a pass over all
// objects divided by N (setting up the estimator and its search tree is
// inside the timing, converting the file's arrays to PCL clouds is not);
// with --per-object also a line "object I ms T" per object from the best
// pass. --out writes each object's output row (float32, the first signature
// for CVFH and OUR-CVFH, zeros where there is none; for normals the normals
// of all points, N x 3 per object) to ROWS.
//
// File layout (little-endian): the 8 bytes "EPPFOBJ1", int64 n_objects,
// int64 n_columns (3: xyz, 6: xyz and normals), int64 offsets[n_objects + 1],
// then float64 values[offsets[n_objects]][n_columns] row by row.

#include <pcl/features/cvfh.h>
#include <pcl/features/esf.h>
#include <pcl/features/gasd.h>
#include <pcl/features/grsd.h>
#include <pcl/features/normal_3d.h>
#include <pcl/features/our_cvfh.h>
#include <pcl/features/vfh.h>
#include <pcl/point_types.h>
#include <pcl/search/kdtree.h>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <fstream>
#include <stdexcept>
#include <string>
#include <vector>

using Cloud = pcl::PointCloud<pcl::PointXYZ>;
using Normals = pcl::PointCloud<pcl::Normal>;

struct Object {
    Cloud::Ptr points{new Cloud};
    Normals::Ptr normals{new Normals};
};

static std::vector<Object> read_objects(const std::string& path)
{
    std::ifstream in(path, std::ios::binary);
    if (!in) throw std::runtime_error("cannot open " + path);
    char magic[8];
    int64_t n = 0, cols = 0;
    in.read(magic, 8);
    in.read(reinterpret_cast<char*>(&n), 8);
    in.read(reinterpret_cast<char*>(&cols), 8);
    if (!in || std::memcmp(magic, "EPPFOBJ1", 8) != 0 || n < 0 || (cols != 3 && cols != 6))
        throw std::runtime_error(path + " is not an objects file (EPPFOBJ1 header)");
    std::vector<int64_t> off(n + 1);
    in.read(reinterpret_cast<char*>(off.data()), 8 * (n + 1));
    if (!in || off[0] != 0) throw std::runtime_error(path + ": bad offsets");
    std::vector<double> v(static_cast<size_t>(off[n] * cols));
    in.read(reinterpret_cast<char*>(v.data()), 8 * v.size());
    if (!in) throw std::runtime_error(path + ": file shorter than its header says");
    std::vector<Object> objects(n);
    for (int64_t k = 0; k < n; ++k) {
        if (off[k + 1] < off[k]) throw std::runtime_error(path + ": offsets decrease");
        for (int64_t i = off[k]; i < off[k + 1]; ++i) {
            const double* r = &v[i * cols];
            objects[k].points->push_back(pcl::PointXYZ(float(r[0]), float(r[1]), float(r[2])));
            pcl::Normal nrm;
            if (cols == 6) nrm = pcl::Normal(float(r[3]), float(r[4]), float(r[5]));
            objects[k].normals->push_back(nrm);
        }
    }
    return objects;
}

static double cpu_seconds()
{
    timespec t;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
    return t.tv_sec + 1e-9 * t.tv_nsec;
}

template <class Sig>
static void keep(const pcl::PointCloud<Sig>& out, std::vector<float>& row)
{
    if (out.empty()) return;  // no signature: the row stays zero
    const float* h = reinterpret_cast<const float*>(&out.points[0]);
    for (size_t i = 0; i < row.size(); ++i) row[i] = h[i];
}

// Compute EST's descriptor of one object into row.
template <class Signature, class Estimator>
static void compute_into(Estimator& est, std::vector<float>& row)
{
    pcl::PointCloud<Signature> out;
    est.compute(out);
    keep(out, row);
}

// The inputs of an estimator that takes normals: the object's points and normals, and a k-d tree.
template <class Estimator>
static void set_inputs(Estimator& est, const Object& o, const pcl::search::KdTree<pcl::PointXYZ>::Ptr& tree)
{
    est.setInputCloud(o.points);
    est.setInputNormals(o.normals);
    est.setSearchMethod(tree);
}

// One object through TASK; its output row goes to row (sized by the caller).
static void describe(const std::string& task, const Object& o, int k, std::vector<float>& row)
{
    pcl::search::KdTree<pcl::PointXYZ>::Ptr tree(new pcl::search::KdTree<pcl::PointXYZ>);
    const float eps = float(5.0 * M_PI / 180.0);
    if (task == "normals") {
        pcl::NormalEstimation<pcl::PointXYZ, pcl::Normal> est;
        Normals out;
        est.setInputCloud(o.points);
        est.setSearchMethod(tree);
        est.setKSearch(k);
        est.compute(out);
        for (size_t i = 0; i < out.size() && 3 * i + 2 < row.size(); ++i) {
            row[3 * i] = out[i].normal_x;
            row[3 * i + 1] = out[i].normal_y;
            row[3 * i + 2] = out[i].normal_z;
        }
    } else if (task == "esf") {
        pcl::ESFEstimation<pcl::PointXYZ, pcl::ESFSignature640> est;
        est.setInputCloud(o.points);
        compute_into<pcl::ESFSignature640>(est, row);
    } else if (task == "gasd") {
        pcl::GASDEstimation<pcl::PointXYZ, pcl::GASDSignature512> est;
        est.setInputCloud(o.points);
        compute_into<pcl::GASDSignature512>(est, row);
    } else if (task == "vfh") {
        pcl::VFHEstimation<pcl::PointXYZ, pcl::Normal, pcl::VFHSignature308> est;
        set_inputs(est, o, tree);
        compute_into<pcl::VFHSignature308>(est, row);
    } else if (task == "cvfh" || task == "cvfh_default") {
        pcl::CVFHEstimation<pcl::PointXYZ, pcl::Normal, pcl::VFHSignature308> est;
        set_inputs(est, o, tree);
        if (task == "cvfh") {  // the reference runs' settings; cvfh_default keeps PCL's
            est.setEPSAngleThreshold(eps);
            est.setCurvatureThreshold(1.0f);
            est.setNormalizeBins(false);
        }
        compute_into<pcl::VFHSignature308>(est, row);
    } else if (task == "ourcvfh") {
        pcl::OURCVFHEstimation<pcl::PointXYZ, pcl::Normal, pcl::VFHSignature308> est;
        set_inputs(est, o, tree);
        est.setEPSAngleThreshold(eps);
        est.setCurvatureThreshold(1.0f);
        est.setAxisRatio(0.8f);
        est.setNormalizeBins(false);
        compute_into<pcl::VFHSignature308>(est, row);
    } else if (task == "grsd") {
        pcl::GRSDEstimation<pcl::PointXYZ, pcl::Normal, pcl::GRSDSignature21> est;
        set_inputs(est, o, tree);
        est.setRadiusSearch(0.05);
        compute_into<pcl::GRSDSignature21>(est, row);
    } else {
        throw std::runtime_error("unknown task " + task);
    }
}

static size_t row_size(const std::string& task, const Object& o)
{
    if (task == "normals") return 3 * o.points->size();
    if (task == "esf") return 640;
    if (task == "gasd") return 512;
    if (task == "grsd") return 21;
    return 308;  // vfh, cvfh, cvfh_default, ourcvfh
}

int main(int argc, char** argv)
{
    if (argc < 3) {
        std::fprintf(stderr, "usage: pcl_bench FILE TASK [--repeats R] [--k K] [--per-object] [--out ROWS]\n");
        return 2;
    }
    const std::string path = argv[1], task = argv[2];
    int repeats = 1, k = 20;
    bool per_object = false;
    std::string out_path;
    for (int a = 3; a < argc; ++a) {
        const std::string opt = argv[a];
        if (opt == "--per-object") per_object = true;
        else if (a + 1 < argc && opt == "--repeats") repeats = std::atoi(argv[++a]);
        else if (a + 1 < argc && opt == "--k") k = std::atoi(argv[++a]);
        else if (a + 1 < argc && opt == "--out") out_path = argv[++a];
        else {
            std::fprintf(stderr, "pcl_bench: unknown option %s\n", opt.c_str());
            return 2;
        }
    }
    if (repeats < 1 || k < 1) {
        std::fprintf(stderr, "pcl_bench: --repeats and --k must be positive\n");
        return 2;
    }
    try {
        const std::vector<Object> objects = read_objects(path);
        const size_t n = objects.size();
        std::vector<std::vector<float>> rows(n);
        for (size_t i = 0; i < n; ++i) rows[i].assign(row_size(task, objects[i]), 0.0f);
        if (n > 0) describe(task, objects[0], k, rows[0]);  // warm up: first-touch pages, lazy initialization
        double best = INFINITY;
        std::vector<double> each(n), best_each(n);
        for (int r = 0; r < repeats; ++r) {
            const double start = cpu_seconds();
            for (size_t i = 0; i < n; ++i) {
                const double t = cpu_seconds();
                describe(task, objects[i], k, rows[i]);
                each[i] = cpu_seconds() - t;
            }
            const double pass = cpu_seconds() - start;
            if (pass < best) {
                best = pass;
                best_each = each;
            }
        }
        std::printf("pcl_bench %s objects %zu ms_per_object %.6f passes %d\n", task.c_str(), n,
                    n ? 1e3 * best / n : 0.0, repeats);
        if (per_object)
            for (size_t i = 0; i < n; ++i) std::printf("object %zu ms %.6f\n", i, 1e3 * best_each[i]);
        if (!out_path.empty()) {
            std::ofstream out(out_path, std::ios::binary);
            for (const auto& row : rows) out.write(reinterpret_cast<const char*>(row.data()), 4 * row.size());
            if (!out) throw std::runtime_error("cannot write " + out_path);
        }
    } catch (const std::exception& e) {
        std::fprintf(stderr, "pcl_bench: %s\n", e.what());
        return 1;
    }
    return 0;
}
