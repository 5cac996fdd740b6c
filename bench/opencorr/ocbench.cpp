// ocbench: OpenCorr 2D DIC benchmark driver (FFTCC or SIFT/FeatureAffine initial guess + ICGN2D1).
// usage: ocbench REF.tif DEF.tif POINTS.csv THREADS [SUBSET_RADIUS=20] [MAX_ITER=10] [CONV=0.001]
// environment (optional):
//   OCBENCH_INIT=fftcc|sift     initial-guess method (default fftcc)
//   OCBENCH_FFTCC_R=N           FFTCC subset radius (window 2N x 2N); default 64 (smallest that catches the 64.3 px shift)
//   OCBENCH_16BIT=1             replace Image2D's 8-bit eg_mat by full-depth data (default: stock Image2D, 8-bit)
//   OCBENCH_OFFSET=v            add v to all grey values after loading (ZNSSD-invariant; works around
//                               OpenCorr's "interpolated value < 0 => out of image" check on 0-valued pixels)
//   OCBENCH_OUT=path.csv        write per-point results
//   OCBENCH_ZNCC_MIN=0.9        validity threshold on OpenCorr's final ZNCC (negative = OpenCorr failure codes)
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>
#include <omp.h>

#include "opencorr.h"

using namespace opencorr;
using clk = std::chrono::steady_clock;

static double ms(clk::time_point a, clk::time_point b)
{
	return std::chrono::duration<double, std::milli>(b - a).count();
}

static const char* env(const char* k, const char* d)
{
	const char* v = getenv(k);
	return (v && *v) ? v : d;
}

int main(int argc, char** argv)
{
	if (argc < 5)
	{
		fprintf(stderr, "usage: %s REF.tif DEF.tif POINTS.csv THREADS [SUBSET_RADIUS=20] [MAX_ITER=10] [CONV=0.001]\n", argv[0]);
		return 2;
	}
	auto t0 = clk::now();
	std::string ref_path = argv[1], tar_path = argv[2], pts_path = argv[3];
	int threads = atoi(argv[4]);
	int radius = argc > 5 ? atoi(argv[5]) : 20;
	int max_iter = argc > 6 ? atoi(argv[6]) : 10;
	float conv = argc > 7 ? (float)atof(argv[7]) : 0.001f;
	std::string init = env("OCBENCH_INIT", "fftcc");
	int fftcc_r = atoi(env("OCBENCH_FFTCC_R", "64"));
	bool full_depth = atoi(env("OCBENCH_16BIT", "0")) != 0;
	float zncc_min = (float)atof(env("OCBENCH_ZNCC_MIN", "0.9"));

	omp_set_num_threads(threads); // OpenCorr has several bare "omp parallel for" (gradient, B-spline, FFTW pool)
	cv::setNumThreads(threads);    // OpenCV-internal threading (SIFT)

	// read points (header line, first two columns x,y)
	std::vector<POI2D> pois;
	{
		std::ifstream f(pts_path);
		if (!f) { fprintf(stderr, "cannot open %s\n", pts_path.c_str()); return 2; }
		std::string line;
		std::getline(f, line);
		while (std::getline(f, line))
		{
			if (line.empty()) continue;
			std::stringstream ss(line);
			std::string sx, sy;
			std::getline(ss, sx, ',');
			std::getline(ss, sy, ',');
			pois.emplace_back(Point2D((float)atof(sx.c_str()), (float)atof(sy.c_str())));
		}
	}

	// load images with OpenCorr's Image2D (cv::imread IMREAD_GRAYSCALE -> 8-bit)
	Image2D ref_img(ref_path);
	Image2D tar_img(tar_path);
	if (full_depth)
	{
		cv::Mat m;
		m = cv::imread(ref_path, cv::IMREAD_ANYDEPTH | cv::IMREAD_GRAYSCALE); cv::cv2eigen(m, ref_img.eg_mat);
		m = cv::imread(tar_path, cv::IMREAD_ANYDEPTH | cv::IMREAD_GRAYSCALE); cv::cv2eigen(m, tar_img.eg_mat);
	}
	float offset = (float)atof(env("OCBENCH_OFFSET", "0"));
	if (offset != 0.f)
	{
		ref_img.eg_mat.array() += offset;
		tar_img.eg_mat.array() += offset;
	}
	auto t_loaded = clk::now();

	// ---- initial guess ----
	auto t_init0 = clk::now();
	double sift_ms = 0, affine_ms = 0;
	if (init == "sift")
	{
		SIFT2D sift;
		sift.setImages(ref_img, tar_img);
		sift.prepare();
		sift.compute();
		auto t_s = clk::now();
		sift_ms = ms(t_init0, t_s);
		FeatureAffine2D fa(radius, radius, threads);
		fa.setImages(ref_img, tar_img);
		fa.setKeypointPair(sift.ref_matched_kp, sift.tar_matched_kp);
		fa.prepare();
		fa.compute(pois);
		affine_ms = ms(t_s, clk::now());
		fprintf(stderr, "sift: %zu matched keypoints, %.1f ms; feature-affine %.1f ms\n", sift.ref_matched_kp.size(), sift_ms, affine_ms);
	}
	else
	{
		FFTCC2D fftcc(fftcc_r, fftcc_r, threads);
		fftcc.setImages(ref_img, tar_img);
		fftcc.compute(pois);
	}
	auto t_init1 = clk::now();

	// ---- ICGN, 1st-order shape function, bicubic B-spline ----
	ICGN2D1 icgn(radius, radius, conv, (float)max_iter, threads);
	icgn.setImages(ref_img, tar_img);
	icgn.prepare(); // gradient maps of ref + B-spline coefficient LUT of tar
	auto t_prep = clk::now();
	icgn.compute(pois);
	auto t_end = clk::now();

	// ---- statistics ----
	size_t n_ok = 0, n_conv = 0;
	double su = 0, sv = 0, suu = 0, svv = 0, sit = 0;
	for (auto& p : pois)
	{
		if (p.result.zncc >= 0.f) n_conv++; // no OpenCorr failure code (-1..-5)
		if (p.result.zncc > zncc_min && std::isfinite(p.deformation.u) && std::isfinite(p.deformation.v))
		{
			n_ok++;
			su += p.deformation.u; sv += p.deformation.v;
			suu += (double)p.deformation.u * p.deformation.u; svv += (double)p.deformation.v * p.deformation.v;
			sit += p.result.iteration;
		}
	}
	double mu = n_ok ? su / n_ok : NAN, mv = n_ok ? sv / n_ok : NAN;
	double stdu = n_ok ? sqrt(std::max(0.0, suu / n_ok - mu * mu)) : NAN;
	double stdv = n_ok ? sqrt(std::max(0.0, svv / n_ok - mv * mv)) : NAN;

	const char* out = getenv("OCBENCH_OUT");
	if (out && *out)
	{
		FILE* f = fopen(out, "w");
		fprintf(f, "x,y,u,v,ux,uy,vx,vy,zncc,iterations,u0,v0\n");
		for (auto& p : pois)
			fprintf(f, "%g,%g,%.7g,%.7g,%.7g,%.7g,%.7g,%.7g,%.7g,%g,%g,%g\n", p.x, p.y, p.deformation.u, p.deformation.v,
				p.deformation.ux, p.deformation.uy, p.deformation.vx, p.deformation.vy,
				p.result.zncc, p.result.iteration, p.result.u0, p.result.v0);
		fclose(f);
	}

	double init_ms = ms(t_init0, t_init1);
	double icgn_ms = ms(t_init1, t_end);
	printf("{\"points\":%zu,\"threads\":%d,\"init\":\"%s\",\"fftcc_radius\":%d,\"subset_radius\":%d,\"full_depth\":%s,"
		"\"load_ms\":%.3f,\"fftcc_ms\":%.3f,\"sift_ms\":%.3f,\"affine_ms\":%.3f,\"icgn_prepare_ms\":%.3f,\"icgn_ms\":%.3f,"
		"\"compute_ms\":%.3f,\"total_ms\":%.3f,\"mean_u\":%.6f,\"mean_v\":%.6f,\"std_u\":%.6f,\"std_v\":%.6f,"
		"\"mean_iterations\":%.4f,\"converged\":%zu,\"valid\":%zu}\n",
		pois.size(), threads, init.c_str(), init == "sift" ? 0 : fftcc_r, radius, full_depth ? "true" : "false",
		ms(t0, t_loaded), init_ms, sift_ms, affine_ms, ms(t_init1, t_prep), icgn_ms,
		ms(t_loaded, t_end), ms(t0, t_end), mu, mv, stdu, stdv, n_ok ? sit / n_ok : NAN, n_conv, n_ok);
	return 0;
}
