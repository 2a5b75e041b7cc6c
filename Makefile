# MirrorCap: `make demo` runs the main job on the embedded sample, `make test` runs the tests.
# Both create the virtual environment .venv on first use (Python 3.11, pinned requirements).

PYTHON ?= $(shell command -v python3.11 2>/dev/null || command -v python3)
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed-$(shell cat requirements.txt requirements-dev.txt pyproject.toml | cksum | cut -d' ' -f1)

.PHONY: demo test bench sample head character rig-clip stress-clips normal-clips compressed-clips occluded-clips extension contact-sheet clean venv

venv: $(STAMP)

$(STAMP): requirements.txt requirements-dev.txt pyproject.toml
	@$(PYTHON) -c 'import sys; sys.exit(0 if sys.version_info[:2] == (3, 11) else "MirrorCap needs Python 3.11 (bpy 5.0.1); set PYTHON=/path/to/python3.11")'
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --disable-pip-version-check -r requirements-dev.txt
	$(PY) -m pip install --quiet --disable-pip-version-check --no-deps -e .
	@rm -f $(VENV)/.installed-*
	@touch $@

demo: $(STAMP)
	$(VENV)/bin/mirrorcap demo --out out

test: $(STAMP)
	$(PY) -m pytest

bench: $(STAMP)
	$(PY) -m benchmarks.run --out bench_results

sample: $(STAMP)
	$(PY) sample_scenes/make_mirror_demo.py

# Re-render the sample rig clip with Cycles (about 12 minutes on 2 cores; frames are cached).
rig-clip: $(STAMP)
	$(PY) sample_scenes/make_rig_clip.py

# The Blender extension: fetch the pinned wheels, validate, one zip per platform into dist/.
extension: $(STAMP)
	$(PY) tools/extension.py build --out dist

clean:
	rm -rf $(VENV) out build dist wheels *.egg-info .pytest_cache

head: $(STAMP)
	$(PY) sample_scenes/make_generic_head.py

# The demo's second character (retarget --method transfer): MakeHuman's base mesh reshaped, landmarks only.
character: $(STAMP)
	$(PY) sample_scenes/make_character.py

contact-sheet: $(STAMP)
	$(PY) sample_scenes/make_contact_sheet.py

# The stress clips of issue #18 (Cycles, cached frames): a dense 720x480 rig at the paper's resolution
# (290 markers of 2.2 mm, mirror planes at 40 deg to the optical axis) and a 1280x720 clip with large head
# motion (+-15 deg yaw, +-10 deg pitch) and expressions 2.5x as fast; and mirror45, held out (200 markers of 3 mm,
# mirrors at 45 deg, 90 frames), rendered after the tracker was tuned; and mirror35, held out too (960x540, 250
# markers of 2.5 mm, mirrors at 35 deg: no marker in both mirrors) and turn, held out too (1600x900, +-18 deg yaw,
# +-12 deg pitch, expressions twice as fast) and sparse, held out and refused (80 dots of 4 mm, face 550 mm away,
# mirrors at 38 deg); close and jaw, held out (a face 480 mm from a wide lens with mirrors at 55 deg; expressions
# 2.5 times as fast at 30 frames/s); webcam, held out (640x360, 120 dots of 3.5 mm); fast540 and fast720, held out
# (expressions 3 and 2.2 times as fast at 30 frames/s; 960x540 with 180 dots of 3 mm, 1280x720 with 240 dots of
# 2.5 mm); wide576, held out (1024x576, 260 dots of 2.4 mm, mirrors at 44 deg, +-14 deg yaw, expressions twice
# as fast; its left view boundary runs through dots); lip648, held out (1152x648, 240 dots of 2.3 mm, mirrors at
# 47 deg, +-16 deg yaw, expressions 2.3 times as fast; rendered after stop 33's detector); tilt630, held out (1120x630,
# 210 dots of 2.6 mm, mirrors at 41 deg, +-13 deg yaw, +-6 deg roll; rendered after stop 33's changes); yaw540 (960x540,
# 230 dots of 2.4 mm, mirrors at 44 deg, +-12 deg pitch; rendered at the start of stop 34, then used to choose among its
# variants) and dots720 (1280x720, 260 dots of 2.2 mm, mirrors at 38 deg; rendered once stop 34's changes were chosen,
# held out); hold648 (1152x648, 250 dots of 2.3 mm, mirrors at 43 deg, +-13 deg yaw; rendered at the start of stop 35,
# where it judged a variant that was not kept) and tempo720 (1280x720, 230 dots of 2.5 mm, mirrors at 46 deg, expressions
# 2.8x as fast; rendered during stop 35, held out from its choices); pitch800 (800x600, a 4:3 sensor, 200 dots of 2.8 mm,
# mirrors at 40 deg, +-12 deg pitch) and vga480 (640x480, 160 dots of 3 mm, mirrors at 48 deg, face 700 mm away, +-14 deg
# yaw, +-6 deg roll), rendered at stop 36 and tuned on by nothing; cam450 (800x450, 150 dots of 3.2 mm, mirrors at 46
# deg, +-12 deg yaw), rendered at stop 37 to check its change and tuned on by nothing; side600 (1024x600, 220 dots of
# 2.4 mm, mirrors at 50 deg, +-14 deg yaw, +-6 deg roll), rendered at stop 38 and the clip its tracker change was found
# on; many1080 (1920x1080, 350 dots of 2 mm, mirrors at 46 deg, 60 frames), rendered at stop 40 and tuned on by
# nothing; askew720 (1280x720, 240 dots of 2.4 mm, a rig set up by hand: mirrors at 38 and 50 deg, tilted 10 deg
# up and 6 deg down, the head 15 mm off the rig's axis and turned 10 deg towards one mirror), rendered at stop 45 and
# tuned on by nothing; hq1 (1024x576, 210 dots of 2.6 mm, mirrors at 43 and 49 deg, the head 8 mm off the axis,
# expressions twice as fast), held out at stop 51, then the clip stop 52's follow-on was found on; hr2 (1152x648, 230
# dots of 2.5 mm, mirrors at 41 and 46 deg, the head 6 mm off the axis and turned 5 deg, the mirror images touching
# the face), rendered after stop 52's change and tuned on by nothing; dense41 (held-out hy11: 720x480 like dense, 280
# dots of 2.2 mm, mirrors at 41 and 39 deg, so at most 3 markers in both mirrors at once, 4 render samples a pixel),
# held out at stop 56, kept at stop 57 for the mirrors' scales linked through the head's motion. About 125 minutes.
stress-clips: $(STAMP)
	$(PY) sample_scenes/make_rig_clip.py --out sample_scenes/stress/dense --size 720 480 --focal 790 \
		--markers 290 --marker-mm 2.2 --mirror-deg 50 --distance 650 --frames 300 --seed 11 --no-scan
	$(PY) sample_scenes/make_rig_clip.py --out sample_scenes/stress/motion --head-deg 10 15 4 --tempo 2.5 --samples 4 \
		--frames 300 --seed 12 --no-scan
	$(PY) sample_scenes/make_rig_clip.py --out sample_scenes/stress/mirror45 --frames 90 --samples 4 --seed 23 \
		--markers 200 --marker-mm 3.0 --mirror-deg 45 --head-deg 8 12 3 --tempo 1.5 --no-scan
	$(PY) sample_scenes/make_rig_clip.py --out sample_scenes/stress/mirror35 --size 960 540 --focal 1000 --markers 250 \
		--marker-mm 2.5 --mirror-deg 35 --distance 600 --head-deg 6 10 3 --tempo 1.2 --frames 90 --samples 4 --seed 31 \
		--no-scan
	$(PY) sample_scenes/make_rig_clip.py --out sample_scenes/stress/turn --size 1600 900 --focal 1600 --markers 220 \
		--marker-mm 2.5 --mirror-deg 42 --distance 680 --head-deg 12 18 5 --tempo 2.0 --frames 120 --samples 4 \
		--seed 51 --no-scan
	$(PY) sample_scenes/make_rig_clip.py --out sample_scenes/stress/sparse --markers 80 --marker-mm 4.0 --mirror-deg 38 \
		--distance 550 --head-deg 5 8 3 --tempo 1.0 --frames 90 --samples 4 --seed 61 --no-scan
	$(PY) sample_scenes/make_rig_clip.py --out sample_scenes/stress/close --focal 950 --distance 480 --mirror-deg 55 \
		--markers 170 --marker-mm 3 --head-deg 10 12 10 --tempo 1.5 --frames 90 --samples 4 --seed 61 --no-scan
	$(PY) sample_scenes/make_rig_clip.py --out sample_scenes/stress/jaw --focal 1200 --distance 560 --mirror-deg 50 \
		--markers 200 --marker-mm 2.5 --head-deg 8 10 6 --tempo 2.5 --frames 90 --samples 4 --seed 71 --no-scan
	$(PY) sample_scenes/make_rig_clip.py --out sample_scenes/stress/webcam --size 640 360 --focal 600 --distance 600 \
		--mirror-deg 45 --markers 120 --marker-mm 3.5 --head-deg 8 10 4 --tempo 1.2 --frames 90 --samples 4 --seed 81 \
		--no-scan
	$(PY) sample_scenes/make_rig_clip.py --out sample_scenes/stress/fast540 --size 960 540 --focal 900 --distance 600 \
		--mirror-deg 42 --markers 180 --marker-mm 3 --head-deg 6 12 5 --tempo 3.0 --frames 90 --samples 4 --seed 91 \
		--no-scan
	$(PY) sample_scenes/make_rig_clip.py --out sample_scenes/stress/fast720 --size 1280 720 --focal 1100 --distance 620 \
		--mirror-deg 47 --markers 240 --marker-mm 2.5 --head-deg 8 8 3 --tempo 2.2 --frames 90 --samples 4 --seed 92 \
		--no-scan
	$(PY) sample_scenes/make_rig_clip.py --out sample_scenes/stress/wide576 --size 1024 576 --focal 950 --distance 580 \
		--mirror-deg 44 --markers 260 --marker-mm 2.4 --head-deg 8 14 4 --tempo 2.0 --frames 90 --samples 4 --seed 93 \
		--no-scan
	$(PY) sample_scenes/make_rig_clip.py --out sample_scenes/stress/lip648 --size 1152 648 --focal 1050 --distance 620 \
		--mirror-deg 47 --markers 240 --marker-mm 2.3 --head-deg 9 16 4 --tempo 2.3 --frames 90 --samples 4 --seed 131 \
		--no-scan
	$(PY) sample_scenes/make_rig_clip.py --out sample_scenes/stress/tilt630 --size 1120 630 --focal 1000 --distance 640 \
		--mirror-deg 41 --markers 210 --marker-mm 2.6 --head-deg 11 13 6 --tempo 1.8 --frames 90 --samples 4 --seed 151 \
		--no-scan
	$(PY) sample_scenes/make_rig_clip.py --out sample_scenes/stress/yaw540 --size 960 540 --focal 880 --distance 630 \
		--mirror-deg 44 --markers 230 --marker-mm 2.4 --head-deg 12 10 5 --tempo 2.0 --frames 90 --samples 4 --seed 171 \
		--no-scan
	$(PY) sample_scenes/make_rig_clip.py --out sample_scenes/stress/dots720 --size 1280 720 --focal 1150 --distance 660 \
		--mirror-deg 38 --markers 260 --marker-mm 2.2 --head-deg 10 12 5 --tempo 2.2 --frames 90 --samples 4 --seed 191 \
		--no-scan
	$(PY) sample_scenes/make_rig_clip.py --out sample_scenes/stress/hold648 --size 1152 648 --focal 1020 --distance 640 \
		--mirror-deg 43 --markers 250 --marker-mm 2.3 --head-deg 9 13 5 --tempo 2.0 --frames 90 --samples 4 --seed 211 \
		--no-scan
	$(PY) sample_scenes/make_rig_clip.py --out sample_scenes/stress/tempo720 --size 1280 720 --focal 1080 --distance 610 \
		--mirror-deg 46 --markers 230 --marker-mm 2.5 --head-deg 8 12 4 --tempo 2.8 --frames 90 --samples 4 --seed 231 \
		--no-scan
	$(PY) sample_scenes/make_rig_clip.py --out sample_scenes/stress/pitch800 --size 800 600 --focal 760 --distance 620 \
		--mirror-deg 40 --markers 200 --marker-mm 2.8 --head-deg 12 10 4 --tempo 1.6 --frames 90 --samples 4 --seed 251 \
		--no-scan
	$(PY) sample_scenes/make_rig_clip.py --out sample_scenes/stress/vga480 --size 640 480 --focal 640 --distance 700 \
		--mirror-deg 48 --markers 160 --marker-mm 3.0 --head-deg 8 14 6 --tempo 2.0 --frames 90 --samples 4 --seed 261 \
		--no-scan
	$(PY) sample_scenes/make_rig_clip.py --out sample_scenes/stress/cam450 --size 800 450 --focal 720 --distance 620 \
		--mirror-deg 46 --markers 150 --marker-mm 3.2 --head-deg 8 12 5 --tempo 1.6 --frames 90 --samples 4 --seed 371 \
		--no-scan
	$(PY) sample_scenes/make_rig_clip.py --out sample_scenes/stress/side600 --size 1024 600 --focal 980 --distance 600 \
		--mirror-deg 50 --markers 220 --marker-mm 2.4 --head-deg 10 14 6 --tempo 2.2 --frames 90 --samples 4 --seed 421 \
		--no-scan
	$(PY) sample_scenes/make_rig_clip.py --out sample_scenes/stress/many1080 --size 1920 1080 --focal 1700 \
		--distance 650 --mirror-deg 46 --markers 350 --marker-mm 2.0 --head-deg 8 12 5 --tempo 1.5 --frames 60 \
		--samples 4 --seed 507 --no-scan
	$(PY) sample_scenes/make_rig_clip.py --out sample_scenes/stress/askew720 --size 1280 720 --focal 1100 \
		--distance 630 --mirror-deg 38 50 --mirror-tilt 10 -6 --head-offset 15 -8 --head-turn 3 10 2 --markers 240 \
		--marker-mm 2.4 --head-deg 9 12 5 --tempo 2.0 --frames 90 --samples 4 --seed 441 --no-scan
	$(PY) sample_scenes/make_rig_clip.py --out sample_scenes/stress/hq1 --size 1024 576 --focal 930 --distance 610 \
		--mirror-deg 43 49 --markers 210 --marker-mm 2.6 --head-deg 10 14 5 --head-offset 8 -5 --tempo 2.0 \
		--frames 75 --samples 4 --seed 5151 --no-scan
	$(PY) sample_scenes/make_rig_clip.py --out sample_scenes/stress/hr2 --size 1152 648 --focal 1050 --distance 630 \
		--mirror-deg 41 46 --markers 230 --marker-mm 2.5 --head-deg 8 16 4 --head-offset -6 4 --head-turn 0 5 0 \
		--tempo 2.2 --frames 90 --samples 4 --seed 7373 --no-scan
	$(PY) sample_scenes/make_rig_clip.py --out sample_scenes/stress/dense41 --size 720 480 --focal 790 \
		--mirror-deg 41 39 --markers 280 --marker-mm 2.2 --head-deg 12 14 5 --tempo 1.5 --frames 90 --samples 4 \
		--seed 20721 --no-scan

# The normal-light clips of issue #21 (Cycles, cached frames): matte dots of four colours on a light skin
# (150 dots) and on a dark skin (180 dots, larger head motion), lit by two studio lamps; and hd, held out (1920x1080,
# medium skin, 180 dots of 3 mm, mirrors at 40 deg, +-14 deg yaw, 90 frames); med720, held out (1280x720, medium skin,
# 170 dots of 2.8 mm, mirrors at 43 deg, +-12 deg yaw, 90 frames; rendered at stop 36); tan720, held out (1280x720,
# a tanned skin of sRGB 190,140,110, 190 dots of 2.7 mm, mirrors at 44 deg, +-12 deg yaw, 90 frames; rendered at
# stop 38); deep720 (1280x720, a deep skin of sRGB 110,75,55, 200 dots of 2.6 mm, mirrors at 42 deg, +-12 deg yaw,
# 90 frames; rendered at stop 38); ruddy540 (960x540, a ruddy skin, 200 dots of 2.8 mm, mirrors at 46 deg; stop 39);
# small540 (960x540, medium skin, 240 dots of 2.2 mm 700 mm away -- 3.2 px across, 2.5-2.8 px in the mirrors: too
# small for the detector under normal light, kept to check that the take says so; stop 40); four576 (1024x576, a
# skin of sRGB 200,150,120, 200 dots of 2.7 mm: 4.0 px; held out at stop 40); rose720 (1280x720, a skin of sRGB
# 215,165,140, 190 dots of 2.5 mm 660 mm away: 4.1 px in the mirrors, 60 frames; held out at stop 41); umber600
# (960x600, a skin of sRGB 125,85,65, 180 dots of 3 mm 680 mm away, mirrors at 42 deg, 60 frames; held out at stop
# 42); blur540n (960x540, a medium skin, 200 dots of 3.2 mm, expressions 2.5x as fast, each frame blurred over a
# 1/60 s shutter; held out at stop 47); touch576 (1024x576, a skin of sRGB 190,140,110, 220 dots of 2.8 mm, mirrors
# at 44 deg, the mirrors' views touching the direct one; held out at stop 47, kept at stop 48); hv2 (1152x648, the dark
# skin, 240 dots of 2.8 mm, mirrors at 45 and 41 deg, the head 5 mm off the axis, +-15 deg yaw; held out at stop 53,
# its identity switches fixed at stop 55); hx4 (1152x648, a skin of sRGB 110,75,58, 280 dots of 2.6 mm, mirrors at
# 44 and 42 deg tilted -3 and 4 deg, +-16 deg pitch; held out at stop 55, kept for a dot split into two labels
# without its rig file); hy2 (1024x576 at a 1400 px focal length, a skin of sRGB 200,160,140, 240 dots of 2.4 mm,
# mirrors at 42 and 40 deg, the head turned 5 deg; held out at stop 56, kept for a silhouette dot paired with a like
# dot's image); hy6 (960x540, a skin of sRGB 90,60,45, 220 dots of 2.6 mm, mirrors at 45 deg, the head turned;
# held out at stop 56, kept for two like dots at the silhouette each paired with the other's image). About 151
# minutes.
normal-clips: $(STAMP)
	$(PY) sample_scenes/make_rig_clip.py --light normal --skin light --out sample_scenes/normal/light --frames 120 \
		--seed 21 --no-scan
	$(PY) sample_scenes/make_rig_clip.py --light normal --skin dark --markers 180 --head-deg 8 10 4 \
		--out sample_scenes/normal/dark --frames 120 --seed 22 --no-scan
	$(PY) sample_scenes/make_rig_clip.py --light normal --skin medium --out sample_scenes/normal/hd --size 1920 1080 \
		--focal 2000 --markers 180 --marker-mm 3.0 --mirror-deg 40 --distance 700 --head-deg 8 14 4 --tempo 1.3 \
		--frames 90 --samples 4 --seed 41 --no-scan
	$(PY) sample_scenes/make_rig_clip.py --light normal --skin medium --out sample_scenes/normal/med720 --size 1280 720 \
		--focal 1150 --markers 170 --marker-mm 2.8 --mirror-deg 43 --distance 640 --head-deg 10 12 5 --tempo 1.6 \
		--frames 90 --samples 4 --seed 301 --no-scan
	$(PY) sample_scenes/make_rig_clip.py --light normal --skin 190,140,110 --out sample_scenes/normal/tan720 \
		--size 1280 720 --focal 1100 --markers 190 --marker-mm 2.7 --mirror-deg 44 --distance 630 --head-deg 10 12 5 \
		--tempo 1.8 --frames 90 --samples 4 --seed 411 --no-scan
	$(PY) sample_scenes/make_rig_clip.py --light normal --skin 110,75,55 --out sample_scenes/normal/deep720 \
		--size 1280 720 --focal 1100 --markers 200 --marker-mm 2.6 --mirror-deg 42 --distance 640 --head-deg 8 12 4 \
		--tempo 2.0 --frames 90 --samples 4 --seed 431 --no-scan
	$(PY) sample_scenes/make_rig_clip.py --light normal --skin 160,110,90 --out sample_scenes/normal/ruddy540 \
		--size 960 540 --focal 820 --markers 200 --marker-mm 2.8 --mirror-deg 46 --distance 620 --head-deg 10 12 7 \
		--tempo 1.8 --frames 90 --samples 4 --seed 481 --no-scan
	$(PY) sample_scenes/make_rig_clip.py --light normal --skin medium --out sample_scenes/normal/small540 \
		--size 960 540 --focal 800 --markers 240 --marker-mm 2.2 --mirror-deg 48 --distance 700 --head-deg 8 14 6 \
		--tempo 1.5 --frames 90 --seed 503 --no-scan
	$(PY) sample_scenes/make_rig_clip.py --light normal --skin 200,150,120 --out sample_scenes/normal/four576 \
		--size 1024 576 --focal 950 --markers 200 --marker-mm 2.7 --mirror-deg 44 --distance 640 --head-deg 8 12 5 \
		--tempo 1.6 --frames 90 --samples 4 --seed 505 --no-scan
	$(PY) sample_scenes/make_rig_clip.py --light normal --skin 215,165,140 --out sample_scenes/normal/rose720 \
		--size 1280 720 --focal 1150 --markers 190 --marker-mm 2.5 --mirror-deg 45 --distance 660 --head-deg 8 12 5 \
		--tempo 1.6 --frames 60 --samples 4 --seed 611 --no-scan
	$(PY) sample_scenes/make_rig_clip.py --light normal --skin 125,85,65 --out sample_scenes/normal/umber600 \
		--size 960 600 --focal 950 --markers 180 --marker-mm 3.0 --mirror-deg 42 --distance 680 --head-deg 9 10 6 \
		--tempo 1.8 --frames 60 --samples 4 --seed 7433 --no-scan
	$(PY) sample_scenes/make_rig_clip.py --light normal --skin medium --out sample_scenes/normal/blur540n \
		--size 960 540 --focal 830 --markers 200 --marker-mm 3.2 --tempo 2.5 --shutter 0.5 --blur-steps 4 \
		--frames 60 --seed 11 --no-scan
	$(PY) sample_scenes/make_rig_clip.py --light normal --skin 190,140,110 --out sample_scenes/normal/touch576 \
		--size 1024 576 --focal 900 --markers 220 --marker-mm 2.8 --mirror-deg 44 --head-deg 10 12 5 --tempo 2 \
		--frames 75 --seed 21 --no-scan
	$(PY) sample_scenes/make_rig_clip.py --light normal --skin dark --out sample_scenes/normal/hv2 --size 1152 648 \
		--markers 240 --marker-mm 2.8 --mirror-deg 45 41 --head-deg 8 15 4 --head-offset -5 4 --tempo 1.3 \
		--frames 90 --samples 4 --seed 3434 --no-scan
	$(PY) sample_scenes/make_rig_clip.py --light normal --skin 110,75,58 --out sample_scenes/normal/hx4 --size 1152 648 \
		--mirror-deg 44 42 --mirror-tilt -3 4 --markers 280 --marker-mm 2.6 --head-deg 16 12 4 --head-turn 6 3 0 \
		--head-offset 2 5 --tempo 1.4 --frames 90 --samples 4 --seed 10606 --no-scan
	$(PY) sample_scenes/make_rig_clip.py --light normal --skin 200,160,140 --out sample_scenes/normal/hy2 --size 1024 576 \
		--mirror-deg 42 40 --markers 240 --marker-mm 2.4 --head-deg 12 14 5 --head-turn 0 -5 0 --tempo 1.2 \
		--frames 90 --samples 4 --seed 20712 --no-scan
	$(PY) sample_scenes/make_rig_clip.py --light normal --skin 90,60,45 --out sample_scenes/normal/hy6 --size 960 540 \
		--focal 900 --mirror-deg 45 45 --markers 220 --marker-mm 2.6 --head-deg 10 12 6 --head-turn -4 0 3 \
		--tempo 1.7 --frames 90 --samples 4 --seed 20716 --no-scan

# Stress clips with an object passed in front of the face (stop 46): a dark sphere -- a hand or a microphone under
# black light -- swept sideways before the lower face (sample_scenes/occlude_clip.py), hiding the mouth's dots from
# the camera for 36-61 frames while the mirrors still see them; the truth's `visible` follows. Half a minute.
occluded-clips: $(STAMP)
	$(PY) sample_scenes/occlude_clip.py sample_scenes/stress/fast720 sample_scenes/occluded/fast720_hand --frames 20 60 \
		--ahead-mm 60
	$(PY) sample_scenes/occlude_clip.py sample_scenes/stress/tempo720 sample_scenes/occluded/tempo720_hand --frames 30 65
	$(PY) sample_scenes/occlude_clip.py sample_scenes/stress/dense sample_scenes/occluded/dense_hand --frames 100 160 \
		--radius-mm 35

# The normal-light clips above as a camera or a screen recorder would keep them (issue #18, stop 41): hd re-encoded
# through Blender's FFmpeg at H.264 CRF 26 and 29 (4.1 and 2.0 Mbit/s at 1080p), light at CRF 26 (3.5 Mbit/s at
# 720p), rose720 at CRF 20 (6.1 Mbit/s), umber600 at CRF 23 (stop 42). The rendered clips are kept at CRF 17. A minute.
compressed-clips: $(STAMP)
	$(PY) sample_scenes/reencode_clip.py sample_scenes/normal/hd sample_scenes/normal/hd_crf26 --quality LOW
	$(PY) sample_scenes/reencode_clip.py sample_scenes/normal/hd sample_scenes/normal/hd_crf29 --quality VERYLOW
	$(PY) sample_scenes/reencode_clip.py sample_scenes/normal/light sample_scenes/normal/light_crf26 --quality LOW
	$(PY) sample_scenes/reencode_clip.py sample_scenes/normal/rose720 sample_scenes/normal/rose720_crf20 --quality HIGH
	$(PY) sample_scenes/reencode_clip.py sample_scenes/normal/umber600 sample_scenes/normal/umber600_crf23 --quality MEDIUM

