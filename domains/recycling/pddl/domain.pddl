;; cbdi's recycling domain: robots fetch plastic litter and put it in bins, on a grid
;; where people walk. Same semantics as the paper's scenario: a move takes 1 time unit,
;; a pickup and a recycle 3; a robot carries at most 3 items; a bin cell is never free,
;; so robots recycle from a cell next to the bin. Cells are named c_X_Y.

(define (domain recycling)
  (:requirements :strips :typing :fluents :durative-actions)

  (:types robot plastic bin cell)

  (:predicates
    (in ?r - robot ?c - cell)            ; where a robot is
    (free ?c - cell)                     ; nothing stands there (no wall, bin, person, robot)
    (near ?c1 - cell ?c2 - cell)         ; 4-adjacent cells
    (litter_pose ?l - plastic ?c - cell) ; litter lying on a cell
    (bin_pose ?b - bin ?c - cell)
    (holding ?r - robot ?l - plastic)
    (recycled ?l - plastic)
    (map_loaded))

  (:functions
    (loaded_amount ?r - robot)           ; items the robot carries
    (detection_depth ?r - robot))

  (:durative-action move
    :parameters (?r - robot ?from ?to - cell)
    :duration (= ?duration 1)
    :condition (and (at start (in ?r ?from))
                    (over all (near ?from ?to))
                    (over all (free ?to)))
    :effect (and (at start (not (in ?r ?from)))
                 (at start (free ?from))
                 (at end (in ?r ?to))
                 (at end (not (free ?to)))))

  (:durative-action litter_pickup
    :parameters (?r - robot ?l - plastic ?c - cell)
    :duration (= ?duration 3)
    :condition (and (at start (< (loaded_amount ?r) 3))
                    (at start (litter_pose ?l ?c))
                    (over all (in ?r ?c)))
    :effect (and (at start (not (litter_pose ?l ?c)))
                 (at end (holding ?r ?l))
                 (at end (increase (loaded_amount ?r) 1))))

  (:durative-action recycle
    :parameters (?r - robot ?l - plastic ?b - bin ?c ?bc - cell)
    :duration (= ?duration 3)
    :condition (and (at start (holding ?r ?l))
                    (over all (in ?r ?c))
                    (over all (bin_pose ?b ?bc))
                    (over all (near ?c ?bc)))
    :effect (and (at start (not (holding ?r ?l)))
                 (at start (decrease (loaded_amount ?r) 1))
                 (at end (recycled ?l)))))
