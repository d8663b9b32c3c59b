"""docs/img/annotate_mvor.jpg: camera 2 of the evaluation sequence, frame 10, with the renderer-1.1 and 1.2 annotations."""
import json
import cv2
import numpy as np

new = json.load(open("data/seq_eval/annotations.json"))
old = json.load(open("/tmp/all_seq_eval/annotations.json"))
mv = new["multiview_images"][10]
panels = []
for title, ann in (("--annotate all (renderer 1.1)", old), ("--annotate mvor (1.2, default)", new)):
    for im in mv["images"]:
        if im["cam_id"] != 2:
            continue
        img = cv2.imread(f"data/seq_eval/{im['file_name']}")
        for a in ann["annotations"]:
            if a["image_id"] != im["id"]:
                continue
            x, y, w, h = map(int, a["bbox"])
            kp = np.reshape(a["keypoints"], (10, 3))
            inside = int((kp[:, 2] > 0).sum())
            if a["person_id"] >= 0:
                col, label = (60, 200, 60), f"id {a['person_id']}: {inside}/10 joints in image"
                for u, v, f in kp:
                    if f == 2:
                        cv2.circle(img, (int(u), int(v)), 4, col, -1)
            else:
                col, label = (160, 160, 160), "box only (id -1)"
            cv2.rectangle(img, (x, y), (x + w - 1, y + h - 1), col, 2)
            (tw, th), _ = cv2.getTextSize(label, cv2.FONT_HERSHEY_SIMPLEX, 0.5, 1)
            tx, ty = min(x, img.shape[1] - tw - 4), min(y + h + th + 6, img.shape[0] - 4)
            cv2.rectangle(img, (tx - 2, ty - th - 4), (tx + tw + 2, ty + 4), (0, 0, 0), -1)
            cv2.putText(img, label, (tx, ty), cv2.FONT_HERSHEY_SIMPLEX, 0.5, col, 1, cv2.LINE_AA)
        cv2.rectangle(img, (0, 0), (img.shape[1], 26), (0, 0, 0), -1)
        cv2.putText(img, title, (8, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.55, (255, 255, 255), 1, cv2.LINE_AA)
        panels.append(img)
sheet = cv2.resize(np.hstack(panels), None, fx=0.75, fy=0.75, interpolation=cv2.INTER_AREA)
cv2.imwrite("docs/img/annotate_mvor.jpg", sheet, [cv2.IMWRITE_JPEG_QUALITY, 85])
print(sheet.shape)
